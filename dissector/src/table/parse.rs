//! Parser of the `*.apt` table files (format: `dissector/msgs/FORMAT.md`).
//!
//! Depends on `std` and `model.rs` only, so the build script can run it and refuse to build a
//! table with errors.

use super::model::*;

/// One error in the table files: where, and what.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TableError {
    /// The file.
    pub file: String,
    /// Its line (from 1).
    pub line: usize,
    /// What is wrong.
    pub msg: String,
}

impl std::fmt::Display for TableError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.file, self.line, self.msg)
    }
}

impl std::error::Error for TableError {}

/// Every error found in the table files, in file order (a table with errors is not built).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TableErrors(pub Vec<TableError>);

impl TableErrors {
    /// The errors.
    pub fn iter(&self) -> std::slice::Iter<'_, TableError> {
        self.0.iter()
    }

    /// How many.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether there are none (never, for a returned error).
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl std::fmt::Display for TableErrors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl std::error::Error for TableErrors {}

/// Where a definition is, for the errors found about it once every file is read.
struct At<'a> {
    file: &'a str,
    line: usize,
    what: String,
}

impl At<'_> {
    fn err(&self, msg: impl std::fmt::Display) -> TableError {
        TableError {
            file: self.file.to_string(),
            line: self.line,
            msg: format!("{}: {msg}", self.what),
        }
    }
}

/// Parse table sources (`(file name, text)`, in order) into [`TableData`], or every error found.
pub fn parse_sources(sources: &[(&'static str, &'static str)]) -> Result<TableData, TableErrors> {
    let mut p = Parser::default();
    for (file, text) in sources {
        p.file(file, text);
    }
    p.finish()
}

#[derive(Default)]
struct Parser {
    data: TableData,
    errors: Vec<TableError>,
    /// Unresolved `enum=`/`flags=` references: (is_enum, name, file, line, msg?, sub?, form, field).
    refs: Vec<Ref>,
    cur: Cur,
}

struct Ref {
    is_enum: bool,
    name: &'static str,
    file: &'static str,
    line: usize,
    target: Target,
    form: usize,
    field: usize,
}

#[derive(Clone, Copy)]
enum Target {
    Msg(usize),
    Sub(usize),
}

#[derive(Default, Clone, Copy)]
enum Cur {
    #[default]
    None,
    Msg(usize),
    Sub(usize),
    /// Inside an `enum` (true) or `flags` (false) definition, for `+` continuation lines.
    Def(bool, usize),
    /// Inside a `devices` block.
    Devices(usize),
}

fn strip_comment(line: &str) -> &str {
    let b = line.as_bytes();
    let mut in_q = false;
    for (i, &c) in b.iter().enumerate() {
        match c {
            b'"' => in_q = !in_q,
            b'#' if !in_q && (i == 0 || b[i - 1].is_ascii_whitespace()) => return &line[..i],
            _ => {}
        }
    }
    line
}

/// Split on whitespace, keeping `"quoted strings"` (and `key="quoted value"`) together.
fn tokens(s: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let b = s.as_bytes();
    let mut i = 0;
    while i < b.len() {
        while i < b.len() && b[i].is_ascii_whitespace() {
            i += 1;
        }
        if i >= b.len() {
            break;
        }
        let start = i;
        let mut in_q = false;
        while i < b.len() && (in_q || !b[i].is_ascii_whitespace()) {
            if b[i] == b'"' {
                in_q = !in_q;
            }
            i += 1;
        }
        out.push(&s[start..i]);
    }
    out
}

/// Parse an integer as written in the table and on the command line: decimal or `0x` hex, an
/// optional `-`, `_` separators allowed.
pub fn parse_int(s: &str) -> Option<i64> {
    let s = s.trim();
    let (neg, s) = match s.strip_prefix('-') {
        Some(r) => (true, r),
        None => (false, s),
    };
    let v = if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        i64::from_str_radix(&h.replace('_', ""), 16).ok()?
    } else {
        s.replace('_', "").parse::<i64>().ok()?
    };
    Some(if neg { -v } else { v })
}

/// A duration written `500ms`, `2s` or `120s`, in milliseconds.
fn parse_ms(s: &str) -> Option<u32> {
    if let Some(ms) = s.strip_suffix("ms") {
        return ms.parse().ok();
    }
    s.strip_suffix('s')?.parse::<u32>().ok()?.checked_mul(1000)
}

fn is_ident(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|c| c.is_ascii_alphanumeric() || c == b'_')
}

/// Decode the hex text of an example (`53, 04, 06 …`) into bytes.
pub fn example_bytes(hex: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::new();
    for tok in hex.split(|c: char| c == ',' || c.is_whitespace()) {
        if tok.is_empty() {
            continue;
        }
        let t = tok.trim_start_matches("0x");
        if t.len() != 2 {
            return Err(format!("`{tok}` is not a hex byte"));
        }
        out.push(u8::from_str_radix(t, 16).map_err(|_| format!("`{tok}` is not a hex byte"))?);
    }
    if out.len() < 6 {
        return Err(format!("{} bytes is shorter than a header", out.len()));
    }
    Ok(out)
}

impl Parser {
    fn err(&mut self, file: &str, line: usize, msg: impl AsRef<str>) {
        self.errors.push(TableError {
            file: file.to_string(),
            line,
            msg: msg.as_ref().to_string(),
        });
    }

    fn file(&mut self, file: &'static str, text: &'static str) {
        self.cur = Cur::None;
        for (i, raw) in text.lines().enumerate() {
            let ln = i + 1;
            let line = strip_comment(raw).trim();
            if line.is_empty() {
                continue;
            }
            let (kw, rest) = match line.split_once(char::is_whitespace) {
                Some((k, r)) => (k, r.trim()),
                None => (line, ""),
            };
            match kw {
                "enum" | "flags" => self.def(file, ln, kw == "enum", rest),
                "+" => match self.cur {
                    Cur::Def(is_enum, idx) => self.def_items(file, ln, is_enum, idx, rest),
                    _ => self.err(
                        file,
                        ln,
                        "`+` continuation outside an enum/flags definition",
                    ),
                },
                "msg" => self.msg(file, ln, rest),
                "devices" | "section" => {
                    let models: Vec<&'static str> = tokens(rest);
                    if models.is_empty() || !models.iter().all(|m| is_ident(m)) {
                        self.err(file, ln, format!("{kw} needs: MODEL [MODEL ...]"));
                    }
                    let source = if kw == "devices" {
                        DeviceSource::List
                    } else {
                        DeviceSource::Section
                    };
                    self.data.devices.push(DeviceGroup {
                        models,
                        source,
                        msgs: vec![],
                        silent: vec![],
                        file,
                        line: ln,
                    });
                    self.cur = Cur::Devices(self.data.devices.len() - 1);
                }
                "msgs" => match self.cur {
                    Cur::Devices(d) => self.data.devices[d].msgs.extend(tokens(rest)),
                    _ => self.err(file, ln, "`msgs` outside a devices block"),
                },
                "silent" => match self.cur {
                    Cur::Devices(d) => self.data.devices[d].silent.extend(tokens(rest)),
                    _ => self.err(file, ln, "`silent` outside a devices block"),
                },
                "sub" => self.sub(file, ln, rest),
                "doc" => match self.cur {
                    Cur::Msg(m) => self.data.msgs[m].doc = rest,
                    Cur::Sub(s) => self.data.subs[s].doc = rest,
                    _ => self.err(file, ln, "`doc` outside a msg/sub"),
                },
                "form" => self.form(file, ln, rest),
                "ex" | "exbad" => self.example(file, ln, kw == "exbad", rest),
                "p1" | "p2" => self.hdr_field(file, ln, kw, rest),
                _ => self.data_field(file, ln, kw, rest),
            }
        }
    }

    fn def(&mut self, file: &'static str, ln: usize, is_enum: bool, rest: &'static str) {
        let (name, items) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
        if !is_ident(name) {
            return self.err(file, ln, format!("bad enum/flags name `{name}`"));
        }
        let dup = if is_enum {
            self.data.enums.iter().any(|e| e.name == name)
        } else {
            self.data.flags.iter().any(|e| e.name == name)
        };
        if dup {
            self.err(file, ln, format!("`{name}` is defined twice"));
        }
        let idx = if is_enum {
            self.data.enums.push(EnumDef {
                name,
                items: vec![],
            });
            self.data.enums.len() - 1
        } else {
            self.data.flags.push(FlagsDef::new(name, vec![]));
            self.data.flags.len() - 1
        };
        self.cur = Cur::Def(is_enum, idx);
        self.def_items(file, ln, is_enum, idx, items);
    }

    fn def_items(
        &mut self,
        file: &'static str,
        ln: usize,
        is_enum: bool,
        idx: usize,
        s: &'static str,
    ) {
        for tok in tokens(s) {
            let Some((v, label)) = tok.split_once('=') else {
                self.err(file, ln, format!("`{tok}` is not VALUE=LABEL"));
                continue;
            };
            if !is_ident(label) {
                self.err(file, ln, format!("bad label `{label}`"));
                continue;
            }
            let Some(v) = parse_int(v) else {
                self.err(file, ln, format!("bad value `{v}`"));
                continue;
            };
            if is_enum {
                let e = &mut self.data.enums[idx];
                if e.items.iter().any(|(x, l)| *x == v || *l == label) {
                    let n = e.name;
                    self.err(
                        file,
                        ln,
                        format!("enum {n}: value {v} or label {label} repeated"),
                    );
                }
                self.data.enums[idx].items.push((v, label));
            } else {
                if v <= 0 {
                    self.err(file, ln, format!("flag mask {v} must be positive"));
                    continue;
                }
                let f = &mut self.data.flags[idx];
                if f.items.iter().any(|(_, l)| *l == label) {
                    let n = f.name;
                    self.err(file, ln, format!("flags {n}: label {label} repeated"));
                }
                self.data.flags[idx].items.push((v as u64, label));
            }
        }
    }

    fn msg(&mut self, file: &'static str, ln: usize, rest: &'static str) {
        let t = tokens(rest);
        if t.len() < 3 {
            return self.err(file, ln, "msg needs: ID NAME DIR");
        }
        let id = match t[0]
            .strip_prefix("0x")
            .and_then(|h| u16::from_str_radix(h, 16).ok())
        {
            Some(id) if t[0].len() == 6 => id,
            _ => {
                return self.err(
                    file,
                    ln,
                    format!("bad message id `{}` (want 0x + 4 hex)", t[0]),
                )
            }
        };
        let name = t[1];
        if !is_ident(name) || name.starts_with("MGMSG") || name.to_ascii_uppercase() != name {
            self.err(
                file,
                ln,
                format!("bad message name `{name}` (UPPER_SNAKE, no MGMSG_)"),
            );
        }
        let dir = match t[2] {
            "h2d" => Dir::HostToDevice,
            "d2h" => Dir::DeviceToHost,
            "both" => Dir::Both,
            d => return self.err(file, ln, format!("bad direction `{d}` (h2d, d2h, both)")),
        };
        let mut m = MsgDef {
            id,
            name,
            dir,
            reply: vec![],
            subs: None,
            revs: Revs::BOTH,
            max_len: None,
            class: Class::default(),
            timeout_ms: None,
            doc: "",
            forms: vec![],
            hdr_form: None,
            data_form: [DataForm::WALK; 256],
            examples: vec![],
            file,
            line: ln,
        };
        for a in &t[3..] {
            match a.split_once('=') {
                Some(("reply", v)) => m.reply = v.split(',').filter(|s| !s.is_empty()).collect(),
                Some(("subs", v)) if is_ident(v) => m.subs = Some(v),
                Some(("class", v)) => match Class::parse(v) {
                    Some(c) => m.class = c,
                    None => self.err(
                        file,
                        ln,
                        format!("bad class `{v}` (status, spontaneous, motion, end_of_move, stop)"),
                    ),
                },
                Some(("timeout", v)) => match parse_ms(v) {
                    Some(t) => m.timeout_ms = Some(t),
                    None => self.err(file, ln, format!("bad timeout `{v}` (e.g. 500ms, 120s)")),
                },
                Some(("maxlen", v)) => match parse_int(v).and_then(|x| u16::try_from(x).ok()) {
                    Some(x) if x > 255 => m.max_len = Some(x),
                    _ => self.err(file, ln, format!("bad maxlen `{v}` (a length over 255)")),
                },
                Some(("rev", v)) => match Revs::parse(v) {
                    Some(r) => m.revs = r,
                    None => self.err(file, ln, format!("bad rev `{v}` (23, 2025 or 23,2025)")),
                },
                _ => self.err(file, ln, format!("unknown msg attribute `{a}`")),
            }
        }
        if let Some(o) = self.data.msgs.iter().find(|o| o.id == id || o.name == name) {
            let (of, ol, on) = (o.file, o.line, o.name);
            self.err(
                file,
                ln,
                format!("{name} 0x{id:04X} clashes with {on} at {of}:{ol}"),
            );
        }
        self.data.msgs.push(m);
        self.cur = Cur::Msg(self.data.msgs.len() - 1);
    }

    fn sub(&mut self, file: &'static str, ln: usize, rest: &'static str) {
        let t = tokens(rest);
        if t.len() != 3 {
            return self.err(file, ln, "sub needs: GROUP SUBID NAME");
        }
        let Some(id) = parse_int(t[1]).and_then(|v| u16::try_from(v).ok()) else {
            return self.err(file, ln, format!("bad sub id `{}`", t[1]));
        };
        let (group, name) = (t[0], t[2]);
        if !is_ident(group) || !is_ident(name) {
            self.err(file, ln, "bad sub group or name");
        }
        if let Some(o) = self
            .data
            .subs
            .iter()
            .find(|o| o.group == group && (o.id == id || o.name == name))
        {
            let (of, ol) = (o.file, o.line);
            self.err(
                file,
                ln,
                format!("sub {group} {name} clashes with the one at {of}:{ol}"),
            );
        }
        self.data.subs.push(SubDef {
            group,
            id,
            name,
            doc: "",
            forms: vec![],
            examples: vec![],
            file,
            line: ln,
        });
        self.cur = Cur::Sub(self.data.subs.len() - 1);
    }

    fn forms_mut(&mut self) -> Option<&mut Vec<Form>> {
        match self.cur {
            Cur::Msg(m) => Some(&mut self.data.msgs[m].forms),
            Cur::Sub(s) => Some(&mut self.data.subs[s].forms),
            _ => None,
        }
    }

    fn form(&mut self, file: &'static str, ln: usize, rest: &'static str) {
        let (k, note) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
        let note = note.trim();
        let note = if note.is_empty() {
            ""
        } else if note.len() >= 2 && note.starts_with('"') && note.ends_with('"') {
            &note[1..note.len() - 1]
        } else {
            self.err(file, ln, "a form note must be in double quotes");
            ""
        };
        let kind = match k {
            "hdr" => FormKind::Header,
            "sub" => FormKind::Sub,
            n if n.ends_with('+') => {
                match parse_int(&n[..n.len() - 1]).and_then(|v| u16::try_from(v).ok()) {
                    Some(l) => FormKind::Open(l),
                    None => {
                        return self.err(
                            file,
                            ln,
                            format!("bad form `{k}` (hdr, sub, a length or LEN+)"),
                        )
                    }
                }
            }
            n => match parse_int(n).and_then(|v| u16::try_from(v).ok()) {
                Some(0) => return self.err(file, ln, "a data form of length 0: use `form hdr`"),
                Some(l) => FormKind::Data(l),
                None => {
                    return self.err(file, ln, format!("bad form `{k}` (hdr, sub or a length)"))
                }
            },
        };
        let is_sub_def = matches!(self.cur, Cur::Sub(_));
        if kind == FormKind::Sub {
            let has_subs = matches!(self.cur, Cur::Msg(m) if self.data.msgs[m].subs.is_some());
            if !has_subs {
                self.err(file, ln, "`form sub` needs `subs=GROUP` on the msg");
            }
        }
        if is_sub_def && kind == FormKind::Sub {
            self.err(file, ln, "a sub's forms are `hdr` or a length");
        }
        let Some(forms) = self.forms_mut() else {
            return self.err(file, ln, "`form` outside a msg/sub");
        };
        if forms.iter().any(|f| f.kind == kind) {
            self.err(file, ln, format!("form `{k}` given twice"));
            return;
        }
        forms.push(Form {
            kind,
            note,
            fields: vec![],
            idx: Default::default(),
            reads: Vec::new(),
        });
    }

    fn push_field(
        &mut self,
        file: &'static str,
        ln: usize,
        name: &'static str,
        loc: Loc,
        ty: Ty,
        attrs: &[&'static str],
    ) {
        let target = match self.cur {
            Cur::Msg(m) => Target::Msg(m),
            Cur::Sub(s) => Target::Sub(s),
            _ => return self.err(file, ln, format!("field `{name}` outside a msg/sub")),
        };
        if !is_ident(name) || name.to_ascii_lowercase() != name {
            self.err(file, ln, format!("bad field name `{name}` (snake_case)"));
        }
        let mut f = Field {
            name,
            loc,
            ty,
            unit: None,
            scale: None,
            enumeration: None,
            flags: None,
            q: None,
            pct_of: None,
            max_of: None,
        };
        let mut pending = vec![];
        for a in attrs {
            match a.split_once('=') {
                Some(("unit", u)) if !u.is_empty() => f.unit = Some(u),
                Some(("scale", s)) => match s.parse::<f64>() {
                    Ok(v) if v.is_finite() && v != 0.0 => f.scale = Some(v),
                    _ => self.err(file, ln, format!("bad scale `{s}`")),
                },
                Some(("enum", e)) => pending.push((true, e)),
                Some(("flags", e)) => pending.push((false, e)),
                Some(("pct_of", m)) => match Maximum::parse(m) {
                    Some(m) => f.pct_of = Some(m),
                    _ => self.err(
                        file,
                        ln,
                        format!("bad `pct_of={m}` (volts or travel, on a % field)"),
                    ),
                },
                Some(("max_of", m)) => match Maximum::parse(m) {
                    Some(m) => f.max_of = Some(m),
                    None => self.err(file, ln, format!("bad `max_of={m}` (volts or travel)")),
                },
                Some(("q", q)) => match Quantity::parse(q) {
                    Some(q) => f.q = Some(q),
                    None => self.err(
                        file,
                        ln,
                        format!("bad `q={q}` (pos, pos/s, vel, acc or jerk)"),
                    ),
                },
                _ => self.err(file, ln, format!("unknown field attribute `{a}`")),
            }
        }
        if let Some(e) = quantity_error(&f) {
            self.err(file, ln, e);
        }
        if matches!(ty, Ty::Str(_) | Ty::Bytes(_) | Ty::Pad(_))
            && (!pending.is_empty() || f.scale.is_some())
        {
            self.err(file, ln, "enum/flags/scale on a str/bytes/pad field");
        }
        let forms = match target {
            Target::Msg(m) => &mut self.data.msgs[m].forms,
            Target::Sub(s) => &mut self.data.subs[s].forms,
        };
        let Some(form_idx) = forms.len().checked_sub(1) else {
            return self.err(file, ln, format!("field `{name}` before any `form`"));
        };
        let form = &mut forms[form_idx];
        let repeated = form.fields.iter().any(|x| x.name == name);
        form.fields.push(f);
        let field_idx = form.fields.len() - 1;
        if repeated {
            self.err(file, ln, format!("field `{name}` repeated in the form"));
        }
        for (is_enum, n) in pending {
            self.refs.push(Ref {
                is_enum,
                name: n,
                file,
                line: ln,
                target,
                form: form_idx,
                field: field_idx,
            });
        }
    }

    fn current_form_kind(&self) -> Option<(FormKind, usize)> {
        let forms = match self.cur {
            Cur::Msg(m) => &self.data.msgs[m].forms,
            Cur::Sub(s) => &self.data.subs[s].forms,
            _ => return None,
        };
        let f = forms.last()?;
        let next = f.fields.iter().map(|x| match x.loc {
            Loc::Data(o) => o as usize + x.ty.width(),
            _ => 0,
        });
        Some((f.kind, next.max().unwrap_or(0)))
    }

    fn hdr_field(&mut self, file: &'static str, ln: usize, kw: &str, rest: &'static str) {
        let t = tokens(rest);
        let Some((&name, attrs)) = t.split_first() else {
            return self.err(file, ln, format!("`{kw}` needs a field name"));
        };
        if !matches!(self.current_form_kind(), Some((FormKind::Header, _))) {
            return self.err(file, ln, format!("`{kw}` is only allowed in `form hdr`"));
        }
        let loc = if kw == "p1" { Loc::P1 } else { Loc::P2 };
        self.push_field(file, ln, name, loc, Ty::Prim(Prim::U8), attrs);
    }

    fn data_field(&mut self, file: &'static str, ln: usize, kw: &'static str, rest: &'static str) {
        let Some(ty) = Ty::parse(kw) else {
            return self.err(file, ln, format!("unknown keyword or type `{kw}`"));
        };
        let t = tokens(rest);
        let (name, attrs): (&'static str, &[&'static str]) = match t.split_first() {
            Some((&n, a)) => (n, a),
            // Reserved bytes need no name of their own.
            None if matches!(ty, Ty::Pad(_)) => ("", &[]),
            None => return self.err(file, ln, "a field needs a name"),
        };
        let off = match self.current_form_kind() {
            Some((FormKind::Data(_) | FormKind::Open(_), off)) => off,
            Some((FormKind::Header, _)) => {
                return self.err(
                    file,
                    ln,
                    "data fields are not allowed in `form hdr` (use p1/p2)",
                )
            }
            Some((FormKind::Sub, _)) => {
                return self.err(
                    file,
                    ln,
                    "`form sub` has no fields: they are in the `sub` definitions",
                )
            }
            None => return self.err(file, ln, "a field outside a form"),
        };
        let Ok(off16) = u16::try_from(off) else {
            return self.err(file, ln, "offset overflow");
        };
        let name = if name.is_empty() {
            &*Box::leak(format!("pad_{off}").into_boxed_str())
        } else {
            name
        };
        self.push_field(file, ln, name, Loc::Data(off16), ty, attrs);
    }

    fn example(&mut self, file: &'static str, ln: usize, bad: bool, rest: &'static str) {
        let (hex, tail) = match rest.split_once(';') {
            Some((h, t)) => (h.trim(), t.trim()),
            None => (rest.trim(), ""),
        };
        if let Err(e) = example_bytes(hex) {
            if !bad {
                self.err(file, ln, format!("example bytes: {e}"));
            }
        }
        let mut ex = Example {
            hex,
            checks: vec![],
            bad_reason: None,
            file,
            line: ln,
        };
        let checks = if bad {
            // Values after a last `;` are checks only when they all look like FIELD=VALUE, so a
            // reason may itself contain `;`.
            let (reason, checks) = match tail.rsplit_once(';') {
                Some((r, c))
                    if !c.trim().is_empty()
                        && tokens(c)
                            .iter()
                            .all(|t| t.split_once('=').is_some_and(|(k, _)| is_ident(k))) =>
                {
                    (r.trim(), c.trim())
                }
                _ => (tail, ""),
            };
            if reason.is_empty() {
                self.err(file, ln, "`exbad` needs `; reason`");
            }
            ex.bad_reason = Some(reason);
            checks
        } else {
            tail
        };
        {
            for tok in tokens(checks) {
                match tok.split_once('=') {
                    Some((k, v)) if is_ident(k) && !v.is_empty() => {
                        ex.checks.push((k, v.trim_matches('"')))
                    }
                    _ => self.err(file, ln, format!("`{tok}` is not FIELD=VALUE")),
                }
            }
        }
        match self.cur {
            Cur::Msg(m) => self.data.msgs[m].examples.push(ex),
            Cur::Sub(s) => self.data.subs[s].examples.push(ex),
            _ => self.err(file, ln, "example outside a msg/sub"),
        }
    }

    fn finish(mut self) -> Result<TableData, TableErrors> {
        for r in std::mem::take(&mut self.refs) {
            let idx = if r.is_enum {
                self.data.enums.iter().position(|e| e.name == r.name)
            } else {
                self.data.flags.iter().position(|e| e.name == r.name)
            };
            let Some(idx) = idx else {
                let what = if r.is_enum { "enum" } else { "flags" };
                self.err(r.file, r.line, format!("unknown {what} `{}`", r.name));
                continue;
            };
            let forms = match r.target {
                Target::Msg(m) => &mut self.data.msgs[m].forms,
                Target::Sub(s) => &mut self.data.subs[s].forms,
            };
            let f = &mut forms[r.form].fields[r.field];
            if r.is_enum {
                f.enumeration = Some(idx);
            } else {
                f.flags = Some(idx);
            }
        }
        let mut errs = vec![];
        let names: Vec<&str> = self.data.msgs.iter().map(|m| m.name).collect();
        for m in &self.data.msgs {
            let at = At {
                file: m.file,
                line: m.line,
                what: m.name.to_string(),
            };
            if m.forms.is_empty() {
                errs.push(at.err("no forms"));
            }
            check_forms(&at, &m.forms, &mut errs);
            for r in &m.reply {
                if !names.contains(r) {
                    errs.push(at.err(format!("reply `{r}` is not a message")));
                }
            }
            if let Some(g) = m.subs {
                if !self.data.subs.iter().any(|s| s.group == g) {
                    errs.push(at.err(format!("no `sub {g} …` definitions")));
                }
            }
        }
        for d in &self.data.devices {
            for m in d.msgs.iter().chain(&d.silent) {
                if !names.contains(m) {
                    errs.push(TableError {
                        file: d.file.to_string(),
                        line: d.line,
                        msg: format!("devices: `{m}` is not a message"),
                    });
                }
            }
        }
        for s in &self.data.subs {
            let at = At {
                file: s.file,
                line: s.line,
                what: format!("sub {} {}", s.group, s.name),
            };
            if s.forms.is_empty() {
                errs.push(at.err("no forms"));
            }
            check_forms(&at, &s.forms, &mut errs);
            for f in &s.forms {
                if let FormKind::Data(_) = f.kind {
                    match f.fields.first() {
                        Some(x) if x.name == "sub_id" && x.ty == Ty::Prim(Prim::U16) => {}
                        _ => errs.push(at.err("a sub's data form starts with `u16 sub_id`")),
                    }
                }
            }
            if !self.data.msgs.iter().any(|m| m.subs == Some(s.group)) {
                errs.push(at.err(format!("no msg has subs={}", s.group)));
            }
        }
        self.errors.extend(errs);
        if self.errors.is_empty() {
            Ok(self.data)
        } else {
            Err(TableErrors(self.errors))
        }
    }
}

fn check_forms(at: &At<'_>, forms: &[Form], errs: &mut Vec<TableError>) {
    for f in forms {
        let open = f
            .fields
            .iter()
            .position(|x| matches!(x.ty, Ty::Array(_, 0)));
        match (f.kind, open) {
            (FormKind::Open(_), Some(i)) if i + 1 == f.fields.len() => {}
            (FormKind::Open(n), _) => errs.push(at.err(format!(
                "form {n}+: its last field (and only that one) is an open array `TYPE[*]`"
            ))),
            (_, Some(_)) => errs.push(at.err(format!(
                "form {}: an open array `TYPE[*]` needs an open form `LEN+`",
                f.label()
            ))),
            _ => {}
        }
        if let FormKind::Data(len) | FormKind::Open(len) = f.kind {
            let sum: usize = f.fields.iter().map(|x| x.ty.width()).sum();
            if sum != len as usize {
                errs.push(at.err(format!(
                    "form {len}: fields add up to {sum} bytes, not {len}"
                )));
            }
        }
    }
}

/// Why a field's `unit=`/`q=` pair is wrong, if it is. APT velocities and accelerations are
/// not counts/s or counts/s² (spec section 8): they carry `q=` and an honest raw unit, and a
/// motion quantity is never a fixed `scale=` (the scaling depends on the controller and stage).
fn quantity_error(f: &Field) -> Option<String> {
    let raw_units = Quantity::ALL.map(|q| q.raw_unit());
    match (f.q, f.unit) {
        (Some(q), u) if u != Some(q.raw_unit()) => Some(format!(
            "`q={}` needs `unit={}` (the raw value's unit)",
            q.as_str(),
            q.raw_unit()
        )),
        (Some(q), _) if f.scale.is_some() || f.enumeration.is_some() || f.flags.is_some() => {
            Some(format!(
                "`q={}` and scale/enum/flags: a motion value converts per stage (section 8)",
                q.as_str()
            ))
        }
        (Some(q), _) if !matches!(f.ty, Ty::Prim(_)) => Some(format!(
            "`q={}` on a field that is not one number",
            q.as_str()
        )),
        (None, Some("counts/s2")) => Some(
            "`unit=counts/s2`: APT accelerations are not counts/s\u{b2} (spec section 8); \
             write `unit=acc_units q=acc`"
                .into(),
        ),
        (None, Some(u)) if u != "counts" && raw_units.contains(&u) => Some(format!(
            "`unit={u}` needs its `q=` (velocities are `unit=vel_units q=vel`, spec section 8)"
        )),
        _ => None,
    }
}
