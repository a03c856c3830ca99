//! `aptscope messages`: the message tables, listed or one message's page (formatted in the
//! dissector's listings; printed here).

use crate::common::{bad, ProtoArg};
use crate::error::Result;
use aptscope_dissector::{listing, Table};
use std::io::{self, BufWriter, Write};

// The options of `messages`.
#[derive(clap::Args)]
pub(crate) struct MessagesArgs {
    /// A message name or id, or a sub-message name (`SETPOINT`, `la:SETPOINT`): show its
    /// fields, forms, revisions, devices, replies and the spec's examples.
    pub(crate) query: Option<String>,
    /// Protocol: apt, elliptec, or auto (default: both, APT first).
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// NDJSON, one object per message and sub-message, with every field.
    #[arg(long)]
    pub(crate) json: bool,
    /// Show each form's fields.
    #[arg(short, long)]
    pub(crate) verbose: bool,
}

/// List the tables, or show what `a.query` names.
pub(crate) fn run(a: MessagesArgs) -> Result<()> {
    let MessagesArgs {
        query,
        proto,
        json,
        verbose,
    } = a;
    match (proto, query) {
        (ProtoArg::Elliptec, None) => ell_messages(json, verbose),
        (ProtoArg::Elliptec, Some(_)) => Err(bad(
            "messages NAME looks up APT messages; `messages --proto elliptec -v` lists every \
             Elliptec command with its fields"
                .into(),
        )),
        (_, Some(q)) => message_page(&q, json),
        (ProtoArg::Auto, None) => {
            messages(json, verbose).and_then(|()| ell_messages(json, verbose))
        }
        (ProtoArg::Apt, None) => messages(json, verbose),
    }
}

/// `messages NAME|ID`: the pages of what the query names.
fn message_page(query: &str, as_json: bool) -> Result<()> {
    let pages = listing::pages(Table::global(), query, as_json).map_err(bad)?;
    let mut out = BufWriter::new(io::stdout().lock());
    for p in pages {
        writeln!(out, "{p}")?;
    }
    Ok(out.flush()?)
}

/// `messages --proto apt`: every message, then every sub-message.
fn messages(as_json: bool, verbose: bool) -> Result<()> {
    let table = Table::global();
    let mut out = BufWriter::new(io::stdout().lock());
    if as_json {
        for l in listing::json_lines(table) {
            writeln!(out, "{l}")?;
        }
    } else {
        out.write_all(listing::text(table, verbose).as_bytes())?;
    }
    Ok(out.flush()?)
}

/// `messages --proto elliptec`: the listing lives in the dissector.
fn ell_messages(as_json: bool, verbose: bool) -> Result<()> {
    let mut out = BufWriter::new(io::stdout().lock());
    if as_json {
        for l in aptscope_dissector::ell::listing::json_lines() {
            writeln!(out, "{l}")?;
        }
    } else {
        out.write_all(aptscope_dissector::ell::listing::text(verbose).as_bytes())?;
    }
    Ok(out.flush()?)
}
