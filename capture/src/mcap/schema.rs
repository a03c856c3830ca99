//! The JSON Schemas of the decoded channels, generated from the message tables to describe
//! the lines `decode --json` writes (the renderer in `dissector::json`): one per APT message
//! and Elliptec command, and one per kind of record that is not a frame.

use aptscope_dissector::detect::Proto;
use aptscope_dissector::ell::table::{Cmd, Kind};
use aptscope_dissector::record::Record;
use aptscope_dissector::table::{Field, FormKind, MsgDef, Prim, Ty};
use aptscope_dissector::{json, Table};
use std::collections::HashSet;
use std::fmt::Write as _;

/// A decoded channel: its topic, and its schema's name and body.
pub(super) struct Schema {
    pub topic: String,
    pub name: String,
    pub body: String,
}

/// The channel a record goes on.
pub(super) fn of(rec: &Record<'_>) -> Schema {
    let t = Table::global();
    let (topic, name, body) = match rec {
        Record::Apt(a) => match a.frame.msg {
            Some(m) => (
                format!("/apt/{}", m.name),
                format!("aptscope.apt.{}", m.name),
                apt_schema(t, m),
            ),
            None => (
                "/apt/unknown".into(),
                "aptscope.apt.unknown".into(),
                apt_unknown_schema(),
            ),
        },
        Record::Ell(e) => match e.frame.cmd {
            Some(c) => (
                format!("/ell/{}", c.code),
                format!("aptscope.ell.{}", c.code),
                ell_schema(Some(c)),
            ),
            None => (
                "/ell/unknown".into(),
                "aptscope.ell.unknown".into(),
                ell_schema(None),
            ),
        },
        Record::Garbage(g) => {
            let p = g.proto.code();
            (
                format!("/{p}/garbage"),
                format!("aptscope.{p}.garbage"),
                garbage_schema(p),
            )
        }
        Record::NoReply(x) => {
            let p = x.proto.code();
            (
                format!("/{p}/diag"),
                format!("aptscope.{p}.diag"),
                late_diag_schema(x.proto),
            )
        }
        Record::Units(_) => (
            "/apt/units".into(),
            "aptscope.apt.units".into(),
            units_schema(),
        ),
        Record::Detect { .. } => (
            "/aptscope/detect".into(),
            "aptscope.detect".into(),
            detect_schema(),
        ),
        Record::Stream { .. } => (
            "/aptscope/stream".into(),
            "aptscope.stream".into(),
            stream_schema(),
        ),
        Record::Input(_) | Record::FileDiag { .. } => (
            "/aptscope/input".into(),
            "aptscope.input".into(),
            input_schema(),
        ),
    };
    Schema { topic, name, body }
}

/// A JSON Schema object under construction: `{"type":"object",…,"properties":{…}}`. Only the
/// constructs Foxglove's JSON Schema reader accepts are used: one `type` per property, arrays
/// of scalars or objects, objects with `properties`.
struct SchemaObj {
    props: String,
    head: String,
}

impl SchemaObj {
    fn new(title: Option<&str>, description: Option<&str>) -> Self {
        let mut head = String::new();
        if let Some(t) = title {
            head.push_str(
                "\"$schema\":\"https://json-schema.org/draft/2020-12/schema\",\"title\":",
            );
            json::string(&mut head, t);
            head.push(',');
        }
        if let Some(d) = description.filter(|d| !d.is_empty()) {
            head.push_str("\"description\":");
            json::string(&mut head, d);
            head.push(',');
        }
        SchemaObj {
            props: String::new(),
            head,
        }
    }

    /// Add a property whose schema is `body` (a JSON object text).
    fn raw(&mut self, name: &str, body: &str) -> &mut Self {
        if !self.props.is_empty() {
            self.props.push(',');
        }
        json::string(&mut self.props, name);
        self.props.push(':');
        self.props.push_str(body);
        self
    }

    /// Add a scalar property.
    fn prop(&mut self, name: &str, ty: &str, description: Option<&str>) -> &mut Self {
        let body = scalar(ty, description);
        self.raw(name, &body)
    }

    fn build(&self) -> String {
        format!(
            "{{{}\"type\":\"object\",\"properties\":{{{}}}}}",
            self.head, self.props
        )
    }
}

fn scalar(ty: &str, description: Option<&str>) -> String {
    let mut s = format!("{{\"type\":\"{ty}\"");
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn string_enum<'a>(labels: impl Iterator<Item = &'a str>, description: Option<&str>) -> String {
    let mut s = String::from("{\"type\":\"string\",\"enum\":[");
    for (i, l) in labels.enumerate() {
        if i > 0 {
            s.push(',');
        }
        json::string(&mut s, l);
    }
    s.push(']');
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn array_of(items: &str, description: Option<&str>) -> String {
    let mut s = format!("{{\"type\":\"array\",\"items\":{items}");
    if let Some(d) = description {
        s.push_str(",\"description\":");
        json::string(&mut s, d);
    }
    s.push('}');
    s
}

fn diag_array() -> String {
    let mut d = SchemaObj::new(None, None);
    d.prop("kind", "string", Some("stable snake_case kind"))
        .prop("offset", "integer", Some("byte offset in the lane"))
        .prop("msg", "string", None);
    array_of(&d.build(), Some("problems found in this record"))
}

/// Properties every decoded record has (as `decode --json` writes them). APT records carry the
/// capture direction as `dir`; Elliptec frames say their direction themselves.
fn common(o: &mut SchemaObj, proto: &str) {
    o.prop("n", "integer", Some("record number in the capture"))
        .raw(
            "proto",
            &string_enum(std::iter::once(proto), Some("protocol")),
        )
        .raw(
            "type",
            &string_enum(["frame", "garbage"].into_iter(), Some("record type")),
        )
        .prop(
            "offset",
            "integer",
            Some("byte offset of the record in its lane's byte stream"),
        )
        .prop(
            "cap_offset",
            "integer",
            Some("byte offset of the record in the whole capture (all lanes, read order)"),
        )
        .prop("len", "integer", Some("record length in bytes"))
        .prop("raw", "string", Some("the bytes, as hex"))
        .prop(
            "ts_ns",
            "integer",
            Some("capture time (ns) of the chunk that completed the record"),
        )
        .prop("stream", "integer", Some("capture stream index"));
    if proto == "apt" {
        o.raw(
            "dir",
            &string_enum(
                ["h2d", "d2h", "unknown"].into_iter(),
                Some("captured direction, else the message's direction in the table"),
            ),
        );
    }
}

fn addr_schema(what: &str) -> String {
    let mut a = SchemaObj::new(None, Some(what));
    a.prop(
        "addr",
        "integer",
        Some("address byte (0x01 host, 0x11 rack, 0x21-0x2A bays, 0x50 USB unit)"),
    )
    .prop("name", "string", Some("host, rack, usb, bay0-bay9 or 0xNN"))
    .prop("bay", "integer", Some("bay number 0-9, for bay addresses"));
    a.build()
}

/// The schema of one APT field's JSON value.
fn apt_field_schema(t: &Table, f: &Field) -> String {
    let mut desc = String::new();
    desc.push_str(&f.ty.name());
    match (f.unit, f.scale) {
        (Some(u), Some(s)) => {
            let _ = write!(desc, "; raw value, x {s} = {u} (see phys)");
        }
        (Some(u), None) => {
            let _ = write!(desc, "; {u}");
        }
        (None, Some(s)) => {
            let _ = write!(desc, "; raw value, scale {s}");
        }
        (None, None) => {}
    }
    let num = |p: Prim| if p == Prim::F32 { "number" } else { "integer" };
    match f.ty {
        Ty::Prim(p) => {
            if let Some(e) = f.enumeration {
                let d = t.enum_def(e);
                let _ = write!(desc, "; enum {} (unknown values as numbers)", d.name);
                string_enum(d.items.iter().map(|(_, l)| *l), Some(&desc))
            } else if let Some(fl) = f.flags {
                let d = t.flags_def(fl);
                let _ = write!(desc, "; flags {}: the names of the set bits", d.name);
                array_of(
                    &string_enum(d.items.iter().map(|(_, l)| *l), None),
                    Some(&desc),
                )
            } else {
                scalar(num(p), Some(&desc))
            }
        }
        Ty::Array(p, _) => array_of(&scalar(num(p), None), Some(&desc)),
        Ty::Str(_) => scalar("string", Some(&desc)),
        Ty::Bytes(_) | Ty::Pad(_) => {
            desc.push_str("; as hex");
            scalar("string", Some(&desc))
        }
    }
}

/// Every field of a message over all its forms (and, for sub-message groups, all the group's
/// sub-messages), each name once (the first definition wins), reserved bytes left out.
fn apt_fields<'t>(t: &'t Table, m: &'t MsgDef) -> Vec<&'t Field> {
    let mut seen = HashSet::new();
    let mut out = vec![];
    let mut add = |fs: &'t [Field]| {
        for f in fs {
            if !matches!(f.ty, Ty::Pad(_)) && seen.insert(f.name) {
                out.push(f);
            }
        }
    };
    for form in &m.forms {
        if form.kind == FormKind::Sub {
            if let Some(g) = m.subs {
                for s in t.subs().iter().filter(|s| s.group == g) {
                    for sf in &s.forms {
                        add(&sf.fields);
                    }
                }
            }
        } else {
            add(&form.fields);
        }
    }
    out
}

/// The JSON Schema of an APT message's decoded records, from the message table.
pub fn apt_schema(t: &Table, m: &MsgDef) -> String {
    let title = format!("APT {} (0x{:04X})", m.name, m.id);
    let mut o = SchemaObj::new(Some(&title), Some(m.doc));
    common(&mut o, "apt");
    o.prop("msgid", "integer", Some("message id"))
        .prop("msgid_hex", "string", None)
        .prop("name", "string", Some("message name (without MGMSG_)"))
        .raw(
            "msg_dir",
            &string_enum(
                std::iter::once(m.dir.as_str()),
                Some("who sends it, per the table"),
            ),
        )
        .raw("src", &addr_schema("source"))
        .raw("dst", &addr_schema("destination"))
        .prop(
            "data_flag",
            "boolean",
            Some("the 0x80 data-packet-follows bit of the destination byte"),
        )
        .prop("data_len", "integer", Some("data packet length"))
        .prop(
            "form_note",
            "string",
            Some("which variant of a multi-form message this is"),
        )
        .prop(
            "channel",
            "integer",
            Some("channel number 1-4 from chan_ident"),
        );
    if m.subs.is_some() {
        let mut s = SchemaObj::new(None, Some("sub-message"));
        s.prop("id", "integer", None).prop("name", "string", None);
        o.raw("sub", &s.build());
    }
    let fields = apt_fields(t, m);
    let mut fo = SchemaObj::new(
        None,
        Some("typed field values: raw numbers, enum labels, lists of set flags"),
    );
    let mut po = SchemaObj::new(None, Some("scaled fields in physical units"));
    let mut any_phys = false;
    for f in &fields {
        fo.raw(f.name, &apt_field_schema(t, f));
        // The table's scale, the stage's conversion (`q=`) or the device's maximum (`pct_of=`).
        if f.scale.is_some() || f.q.is_some() || f.pct_of.is_some() {
            let unit = match (f.q, f.pct_of) {
                (Some(_), _) => Some("the stage's unit (mm, deg and their rates)"),
                (None, Some(_)) => Some("V or µm of the device's maximum"),
                (None, None) => f.unit,
            };
            let mut v = SchemaObj::new(None, unit);
            v.prop("value", "number", unit).prop("unit", "string", None);
            po.raw(f.name, &v.build());
            any_phys = true;
        }
    }
    o.raw("fields", &fo.build());
    if any_phys {
        o.raw("phys", &po.build());
    }
    let coded = fields
        .iter()
        .filter(|f| f.enumeration.is_some() || f.flags.is_some());
    codes_schema(&mut o, coded.map(|f| f.name));
    apt_pairing(&mut o);
    o.raw("diag", &diag_array());
    o.build()
}

/// `codes`: the number of each enum or flag field named in `fields` (when there are any).
fn codes_schema<'a>(o: &mut SchemaObj, names: impl Iterator<Item = &'a str>) {
    let mut co = SchemaObj::new(None, Some("numbers of the enum and flag fields"));
    let mut any = false;
    for n in names {
        co.prop(n, "integer", None);
        any = true;
    }
    if any {
        o.raw("codes", &co.build());
    }
}

/// What pairing adds to an APT frame.
fn apt_pairing(o: &mut SchemaObj) {
    o.prop(
        "pair",
        "integer",
        Some("record number of the request this reply answers, or of the reply to this request"),
    )
    .prop(
        "latency_ms",
        "number",
        Some("time between the request and its reply"),
    )
    .prop(
        "pair_other_address",
        "boolean",
        Some("the reply came from another address than the request went to"),
    );
}

pub(super) fn apt_unknown_schema() -> String {
    let mut o = SchemaObj::new(
        Some("APT frame of an unknown message id"),
        Some("a frame whose message id the table lacks; data shown in raw"),
    );
    common(&mut o, "apt");
    o.prop("msgid", "integer", Some("message id"))
        .prop("msgid_hex", "string", None)
        .prop("name", "string", Some("null: the table lacks this id"))
        .raw("src", &addr_schema("source"))
        .raw("dst", &addr_schema("destination"))
        .prop("data_flag", "boolean", None)
        .prop("data_len", "integer", None)
        .raw("fields", &SchemaObj::new(None, None).build());
    apt_pairing(&mut o);
    o.raw("diag", &diag_array());
    o.build()
}

pub(super) fn garbage_schema(proto: &str) -> String {
    let mut o = SchemaObj::new(
        Some(&format!("{proto} garbage")),
        Some("bytes that are not part of any frame"),
    );
    common(&mut o, proto);
    if proto == "ell" {
        o.prop("text", "string", Some("the bytes as text"));
    }
    o.raw("diag", &diag_array());
    o.build()
}

pub(super) fn late_diag_schema(proto: Proto) -> String {
    let mut o = SchemaObj::new(
        Some(&format!("{} late diagnostic", proto.name())),
        Some("a problem found later about an earlier record (a request that got no reply)"),
    );
    o.raw(
        "proto",
        &string_enum(std::iter::once(proto.code()), Some("protocol")),
    )
    .raw("type", &string_enum(std::iter::once("diag"), None))
    .prop(
        "ref",
        "integer",
        Some("record number the diagnostic is about"),
    )
    .prop("stream", "integer", Some("capture stream of that record"))
    .raw("diag", &diag_array());
    o.build()
}

/// A units notice: what converts a device's motion values from the next frame on.
fn units_schema() -> String {
    let mut o = SchemaObj::new(
        Some("APT units"),
        Some("the conversion of a device's motion values from now on, or why they stay raw"),
    );
    o.raw("type", &string_enum(std::iter::once("units"), None))
        .prop("stream", "integer", Some("capture stream index"))
        .raw("addr", &addr_schema("the device"))
        .prop("model", "string", Some("as HW_GET_INFO names it"))
        .prop("stage", "string", None)
        .prop(
            "family",
            "string",
            Some("the controller family's conversion rules"),
        )
        .prop("counts_per_unit", "number", None)
        .prop("unit", "string", Some("mm or deg"))
        .prop("raw", "string", Some("why the values stay raw"));
    o.build()
}

/// The protocol detector's verdict.
fn detect_schema() -> String {
    let mut o = SchemaObj::new(
        Some("aptscope protocol detection"),
        Some("the protocol chosen from the first bytes"),
    );
    o.raw("type", &string_enum(std::iter::once("detect"), None))
        .raw(
            "proto",
            &string_enum(
                [Proto::Apt.code(), Proto::Elliptec.code()].into_iter(),
                None,
            ),
        )
        .prop("certain", "boolean", Some("false: a best guess"))
        .prop(
            "apt",
            "number",
            Some("share of the sample that frames as APT"),
        )
        .prop(
            "ell",
            "number",
            Some("share of the sample that frames as Elliptec"),
        );
    o.build()
}

/// A stream (port, device) of the capture.
fn stream_schema() -> String {
    let mut o = SchemaObj::new(
        Some("aptscope stream"),
        Some("a port or device of the capture"),
    );
    o.raw("type", &string_enum(std::iter::once("stream"), None))
        .prop("stream", "integer", Some("capture stream index"))
        .prop("stream_name", "string", None)
        .prop("settings", "string", Some("line settings"));
    o.build()
}

/// A problem of the input capture file.
fn input_schema() -> String {
    let mut o = SchemaObj::new(
        Some("aptscope input diagnostic"),
        Some("a problem of the capture file itself"),
    );
    o.raw("type", &string_enum(std::iter::once("input"), None))
        .raw("diag", &diag_array());
    o.build()
}

fn ell_field_schema(kind: Kind) -> String {
    let (ty, d): (&str, String) = match kind {
        Kind::Hex => ("integer", "hex number".into()),
        Kind::Signed => ("integer", "signed number".into()),
        Kind::Dec => ("string", "decimal digits as written".into()),
        Kind::Addr => ("string", "bus address 0-F".into()),
        Kind::Status => (
            "string",
            "status code name (OK, BUSY, OUT_OF_RANGE ...)".into(),
        ),
        Kind::Model => ("integer", "module type: ELL number".into()),
        Kind::Firmware => (
            "integer",
            "firmware release: high nibble major, low minor".into(),
        ),
        Kind::ThreadHw => (
            "integer",
            "packed thread (bit 7) and hardware release".into(),
        ),
        Kind::Position => (
            "integer",
            "encoder pulses (in mm or deg under phys once the module is known)".into(),
        ),
        Kind::Period => (
            "integer",
            "drive period: frequency = 14740000 / period Hz".into(),
        ),
        Kind::Current => ("integer", "motor current: 1866 per ampere".into()),
        Kind::Bool => ("integer", "0 or 1".into()),
        Kind::Percent => ("integer", "percent".into()),
        Kind::Minutes => ("integer", "minutes".into()),
        Kind::HomeDir => (
            "integer",
            "home direction: 0 clockwise, 1 counter-clockwise".into(),
        ),
        Kind::Raw => ("string", "binary data as hex".into()),
    };
    scalar(ty, Some(&d))
}

/// The JSON Schema of an Elliptec command's (or reply's) decoded records; `None` for commands
/// the manual lacks.
pub fn ell_schema(cmd: Option<&Cmd>) -> String {
    let title = match cmd {
        Some(c) => format!("Elliptec {} {}", c.code, c.name),
        None => "Elliptec unknown command".to_string(),
    };
    let mut o = SchemaObj::new(Some(&title), cmd.map(|c| c.doc));
    common(&mut o, "ell");
    o.prop(
        "text",
        "string",
        Some("the frame as text, terminator included"),
    )
    .prop("addr", "string", Some("bus address 0-F"))
    .raw(
        "dir",
        &string_enum(
            ["h2d", "d2h"].into_iter(),
            Some("h2d for lower-case commands, d2h for replies"),
        ),
    )
    .prop("cmd", "string", Some("the two-letter mnemonic"))
    .prop("name", "string", Some("the command's name"));
    let mut fo = SchemaObj::new(None, Some("typed field values"));
    let mut po = SchemaObj::new(None, Some("positions in mm, deg or slots"));
    let mut any_phys = false;
    for f in cmd.map_or(&[][..], |c| c.fields) {
        fo.raw(f.name, &ell_field_schema(f.kind));
        if f.kind == Kind::ThreadHw {
            fo.raw(
                "thread",
                &string_enum(["metric", "imperial"].into_iter(), None),
            );
            fo.prop("hw_release", "integer", Some("hardware release"));
        }
        if f.kind == Kind::Model {
            fo.prop(
                &format!("{}_name", f.name),
                "string",
                Some("the model as named: ELL14"),
            );
        }
        if f.kind == Kind::Firmware {
            fo.prop(
                &format!("{}_version", f.name),
                "string",
                Some("the release as major.minor: 1.5"),
            );
        }
        if f.kind == Kind::Raw {
            let mut p = SchemaObj::new(None, None);
            p.prop("period", "integer", Some("drive period"))
                .prop("current", "integer", Some("1866 per ampere"))
                .prop("hz", "number", Some("14740000 / period"))
                .prop("amps", "number", None);
            fo.raw(
                "curve_points",
                &array_of(&p.build(), Some("the current curve, point by point")),
            );
        }
        if f.kind == Kind::Position {
            let mut v = SchemaObj::new(None, None);
            v.prop("value", "number", None)
                .prop("unit", "string", Some("mm, deg or slot"));
            po.raw(f.name, &v.build());
            any_phys = true;
        }
    }
    o.raw("fields", &fo.build());
    if any_phys {
        o.raw("phys", &po.build());
    }
    let fields = cmd.map_or(&[][..], |c| c.fields);
    let coded = fields.iter().filter(|f| f.kind == Kind::Status);
    codes_schema(&mut o, coded.map(|f| f.name));
    let mut mo = SchemaObj::new(None, Some("what the bus knows of the module"));
    mo.prop(
        "first_addr",
        "integer",
        Some("the address it was first seen at"),
    )
    .prop("model", "string", None)
    .prop("serial", "string", None);
    o.raw("module", &mo.build())
        .prop(
            "pair",
            "integer",
            Some("record number of the command this reply answers"),
        )
        .prop("latency_ms", "number", Some("time since that command"))
        .prop(
            "interim",
            "boolean",
            Some("a busy status before the final reply"),
        )
        .raw("diag", &diag_array());
    o.build()
}
