//! `aptscope`: the command line. Parses arguments and calls the libraries.
#![forbid(unsafe_code)]

use aptscope_capture::{ByteSource, InputFormat};
use aptscope_dissector::apt::{encode, Addr, FieldValue};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format, Pipeline};
use aptscope_dissector::table::{Form, FormKind, MsgDef};
use aptscope_dissector::{json, Table};
use clap::{Parser, Subcommand};
use std::io::{self, BufWriter, Write};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "aptscope",
    version,
    about = "Protocol analyser for Thorlabs APT and Elliptec serial traffic"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ProtoArg {
    Auto,
    Apt,
    Elliptec,
}

#[derive(Subcommand)]
enum Cmd {
    /// Decode a byte stream: one line per frame (or NDJSON with --json).
    Decode {
        /// Input file, or `-` for standard input.
        #[arg(default_value = "-")]
        file: String,
        /// The input is hex text (any whitespace) instead of raw bytes.
        #[arg(long)]
        hex: bool,
        /// Write NDJSON, one object per frame or garbage record.
        #[arg(long)]
        json: bool,
        /// Protocol of the stream (default: detected from the first 4 KiB).
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
    },
    /// List the message table.
    Messages {
        /// NDJSON, one object per message and sub-message, with every field.
        #[arg(long)]
        json: bool,
        /// Show each form's fields.
        #[arg(short, long)]
        verbose: bool,
    },
    /// Build a frame from field values and print it as hex.
    Encode {
        /// Message name (`MOT_MOVE_ABSOLUTE`, `MGMSG_` prefix optional).
        name: String,
        /// Field values: `name=value` (numbers, `0x` hex, enum labels, flags `A|B`).
        values: Vec<String>,
        /// Destination: host, rack, usb, bay0…bay9 or a byte value.
        #[arg(long)]
        dest: Option<String>,
        /// Source: host, rack, usb, bay0…bay9 or a byte value.
        #[arg(long)]
        source: Option<String>,
        /// Form to use: `hdr` or a data length (default: the first that has all given fields).
        #[arg(long)]
        form: Option<String>,
        /// Sub-message name, for messages with sub-messages (LA_, TEC_, QUAD_, PZMOT_ …PARAMS).
        #[arg(long)]
        sub: Option<String>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Decode {
            file,
            hex,
            json,
            proto,
        } => decode(&file, hex, json, proto),
        Cmd::Messages { json, verbose } => messages(json, verbose),
        Cmd::Encode {
            name,
            values,
            dest,
            source,
            form,
            sub,
        } => encode_cmd(
            &name,
            &values,
            dest.as_deref(),
            source.as_deref(),
            form.as_deref(),
            sub.as_deref(),
        ),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("aptscope: {e}");
            ExitCode::FAILURE
        }
    }
}

fn decode(file: &str, hex: bool, as_json: bool, proto: ProtoArg) -> io::Result<()> {
    let fmt = if hex {
        InputFormat::Hex
    } else {
        InputFormat::Raw
    };
    let mut src = ByteSource::open(file, fmt)
        .map_err(|e| io::Error::new(e.kind(), format!("{file}: {e}")))?;
    let mut out = BufWriter::with_capacity(1 << 16, io::stdout().lock());
    let proto = match proto {
        ProtoArg::Auto => None,
        ProtoArg::Apt => Some(Proto::Apt),
        ProtoArg::Elliptec => Some(Proto::Elliptec),
    };
    let mut p = Pipeline::new(proto, if as_json { Format::Json } else { Format::Text });
    let mut emit = |line: &str| -> io::Result<()> {
        out.write_all(line.as_bytes())?;
        out.write_all(b"\n")
    };
    while let Some((chunk, diags)) = src.next_chunk()? {
        for d in diags {
            p.input_diag(d, &mut emit)?;
        }
        p.push(chunk, None, &mut emit)?;
    }
    p.finish(&mut emit)?;
    out.flush()
}

fn form_label(f: &Form) -> String {
    match f.kind {
        FormKind::Header => "hdr".into(),
        FormKind::Data(n) => n.to_string(),
        FormKind::Sub => "sub".into(),
    }
}

fn messages(as_json: bool, verbose: bool) -> io::Result<()> {
    let table = Table::global();
    let mut out = BufWriter::new(io::stdout().lock());
    let mut line = String::new();
    if as_json {
        for m in table.msgs() {
            line.clear();
            json::msg_def(&mut line, table, m);
            writeln!(out, "{line}")?;
        }
        for s in table.subs() {
            line.clear();
            json::sub_def(&mut line, table, s);
            writeln!(out, "{line}")?;
        }
        return out.flush();
    }
    let mut msgs: Vec<&MsgDef> = table.msgs().iter().collect();
    msgs.sort_by_key(|m| m.id);
    for m in msgs {
        let forms: Vec<String> = m.forms.iter().map(form_label).collect();
        let replies: Vec<&str> = table.replies_of(m).iter().map(|r| r.name).collect();
        let reply = if replies.is_empty() {
            String::new()
        } else {
            format!(" → {}", replies.join(","))
        };
        writeln!(
            out,
            "0x{:04X}  {:<40} {:<4}  {:<10}{reply}",
            m.id,
            m.name,
            m.dir.as_str(),
            forms.join("|")
        )?;
        if verbose {
            if !m.doc.is_empty() {
                writeln!(out, "        {}", m.doc)?;
            }
            for f in &m.forms {
                let fields: Vec<String> = f
                    .fields
                    .iter()
                    .map(|x| format!("{}:{}", x.name, x.ty.name()))
                    .collect();
                writeln!(out, "        [{}] {}", form_label(f), fields.join(" "))?;
            }
        }
    }
    for s in table.subs() {
        let forms: Vec<String> = s.forms.iter().map(form_label).collect();
        writeln!(
            out,
            "  sub {:<6} 0x{:04X}  {:<32} {}",
            s.group,
            s.id,
            s.name,
            forms.join("|")
        )?;
    }
    out.flush()
}

fn bad(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

fn encode_cmd(
    name: &str,
    values: &[String],
    dest: Option<&str>,
    source: Option<&str>,
    form: Option<&str>,
    sub: Option<&str>,
) -> io::Result<()> {
    let table = Table::global();
    let m = table
        .msg_by_name(name)
        .ok_or_else(|| bad(format!("no message named {name}")))?;
    let pairs: Vec<(&str, &str)> = values
        .iter()
        .map(|v| {
            v.split_once('=')
                .ok_or_else(|| bad(format!("`{v}` is not name=value")))
        })
        .collect::<Result<_, _>>()?;
    let sub_def = match (sub, m.subs) {
        (Some(s), Some(g)) => Some(
            table
                .sub_by_name(g, s)
                .ok_or_else(|| bad(format!("no sub-message {s} in group {g}")))?,
        ),
        (Some(_), None) => return Err(bad(format!("{} has no sub-messages", m.name))),
        (None, _) => None,
    };
    let has_all = |f: &Form| {
        pairs
            .iter()
            .all(|(k, _)| f.fields.iter().any(|x| x.name == *k))
    };
    // Candidate forms: the sub's data forms for SET/GET of a sub group, else the message's own.
    let mut cands: Vec<&Form> = m.forms.iter().filter(|f| f.kind != FormKind::Sub).collect();
    if let Some(s) = sub_def {
        if m.forms.iter().any(|f| f.kind == FormKind::Sub) {
            cands = s.forms.iter().collect();
        }
    }
    let chosen = match form {
        Some("hdr") => cands.iter().find(|f| f.kind == FormKind::Header),
        Some(n) => {
            let n: u16 = n
                .parse()
                .map_err(|_| bad(format!("--form takes hdr or a length, not {n}")))?;
            cands.iter().find(|f| f.kind == FormKind::Data(n))
        }
        None => cands
            .iter()
            .find(|f| has_all(f) && (!pairs.is_empty() || f.kind == FormKind::Header))
            .or_else(|| cands.iter().find(|f| has_all(f))),
    }
    .ok_or_else(|| {
        let labels: Vec<String> = cands.iter().map(|f| form_label(f)).collect();
        bad(format!(
            "no form of {} fits (forms: {}; use --sub for sub-messages)",
            m.name,
            labels.join(", ")
        ))
    })?;
    let mut vals: Vec<(&str, FieldValue)> = vec![];
    if let Some(s) = sub_def {
        if chosen.fields.iter().any(|f| f.name == "sub_id")
            && !pairs.iter().any(|(k, _)| *k == "sub_id")
        {
            vals.push(("sub_id", FieldValue::Int(s.id as i64)));
        }
    }
    for (k, v) in &pairs {
        let f = chosen
            .fields
            .iter()
            .find(|f| f.name == *k)
            .ok_or_else(|| bad(format!("no field {k}")))?;
        vals.push((
            k,
            FieldValue::from_text(table, f, v).map_err(|e| bad(e.to_string()))?,
        ));
    }
    let to_host = m.dir == aptscope_dissector::table::Dir::DeviceToHost;
    let addr = |s: Option<&str>, default: Addr| -> io::Result<u8> {
        match s {
            None => Ok(default.byte()),
            Some(t) => Addr::parse(t)
                .map(Addr::byte)
                .ok_or_else(|| bad(format!("bad address {t}"))),
        }
    };
    let (dd, ds) = if to_host {
        (Addr::Host, Addr::Usb)
    } else {
        (Addr::Usb, Addr::Host)
    };
    let bytes = encode(chosen, &vals, m.id, addr(dest, dd)?, addr(source, ds)?)
        .map_err(|e| bad(e.to_string()))?;
    let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
    println!("{}", hex.join(" "));
    Ok(())
}
