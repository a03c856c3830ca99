//! `aptscope encode`: a frame built from field values.

use crate::common::{bad, ProtoArg};
use crate::error::Result;
use aptscope_dissector::apt::{encode_named_report, Addr, Named};
use aptscope_dissector::Table;
use std::io::{self, Write};

// The options of `encode`.
#[derive(clap::Args)]
pub(crate) struct EncodeArgs {
    /// Protocol: apt (default) or elliptec (`encode --proto elliptec ADDR CMD field=value…`).
    #[arg(long, value_enum, default_value_t = ProtoArg::Apt)]
    pub(crate) proto: ProtoArg,
    /// Message name (`MOT_MOVE_ABSOLUTE`, `MGMSG_` prefix optional); Elliptec: the address.
    pub(crate) name: String,
    /// Field values: `name=value` (numbers, `0x` hex, enum labels, flags `A|B`); Elliptec:
    /// the command (`ma`) first.
    pub(crate) values: Vec<String>,
    /// Destination: host, rack, usb, bay0…bay9 or a byte value.
    #[arg(long)]
    pub(crate) dest: Option<String>,
    /// Source: host, rack, usb, bay0…bay9 or a byte value.
    #[arg(long)]
    pub(crate) source: Option<String>,
    /// Form to use: `hdr` or a data length (default: the first that has all given fields).
    #[arg(long)]
    pub(crate) form: Option<String>,
    /// Sub-message name, for messages with sub-messages (LA_, TEC_, QUAD_, PZMOT_ …PARAMS).
    #[arg(long)]
    pub(crate) sub: Option<String>,
}

/// Encode the frame `a` describes and print it.
pub(crate) fn run(a: EncodeArgs) -> Result<()> {
    if a.proto == ProtoArg::Elliptec {
        return match (&a.dest, &a.source, &a.form, &a.sub) {
            (None, None, None, None) => ell_encode(&a.name, &a.values),
            _ => Err(bad(
                "--dest, --source, --form and --sub are APT options".into()
            )),
        };
    }
    encode_cmd(
        &a.name,
        &a.values,
        a.dest.as_deref(),
        a.source.as_deref(),
        a.form.as_deref(),
        a.sub.as_deref(),
    )
}

/// `encode --proto elliptec ADDR CMD field=value…`: the frame as text (escaped CR LF for
/// replies), or as hex when it holds binary data (`C1`/`C2`).
fn ell_encode(addr: &str, args: &[String]) -> Result<()> {
    use aptscope_dissector::ell::encode;
    let (cmd, values) = args
        .split_first()
        .ok_or_else(|| bad("usage: encode --proto elliptec ADDR CMD [field=value …]".into()))?;
    let bytes = encode::assignments(values)
        .and_then(|v| encode::encode(addr, cmd, &v))
        .map_err(|e| bad(e.to_string()))?;
    Ok(writeln!(io::stdout(), "{}", encode::display(&bytes))?)
}

fn encode_cmd(
    name: &str,
    values: &[String],
    dest: Option<&str>,
    source: Option<&str>,
    form: Option<&str>,
    sub: Option<&str>,
) -> Result<()> {
    let table = Table::global();
    let m = table.msg_by_name(name).ok_or_else(|| {
        bad(aptscope_dissector::apt::EncodeError::unknown_message(table, name).to_string())
    })?;
    let pairs: Vec<(&str, &str)> = values
        .iter()
        .map(|v| {
            v.split_once('=')
                .ok_or_else(|| bad(format!("`{v}` is not name=value")))
        })
        .collect::<Result<_, _>>()?;
    let to_host = m.dir == aptscope_dissector::table::Dir::DeviceToHost;
    let addr = |s: Option<&str>, default: Addr| -> Result<u8> {
        match s {
            None => Ok(default.byte()),
            Some(t) => Addr::parse(t).map(Addr::byte).ok_or_else(|| {
                bad(format!(
                    "bad address {t}: give host, rack, usb, bay0…bay9 or a byte value \
                     (0x00–0xFF, e.g. 0x50)"
                ))
            }),
        }
    };
    let (dd, ds) = if to_host {
        (Addr::Host, Addr::Usb)
    } else {
        (Addr::Usb, Addr::Host)
    };
    let (bytes, zero) = encode_named_report(
        table,
        &Named {
            name,
            sub,
            values: &pairs,
            form,
            dst: addr(dest, dd)?,
            src: addr(source, ds)?,
        },
    )
    .map_err(|e| bad(e.to_string()))?;
    if !zero.is_empty() {
        eprintln!("fields not given, set to 0: {}", zero.join(", "));
    }
    let hex: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
    Ok(writeln!(io::stdout(), "{}", hex.join(" "))?)
}
