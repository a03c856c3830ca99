//! `aptscope stats`: counts, bytes, latencies, diagnostics and rates of a capture.

use crate::common::{compile_filter, fatal, open_opts, proto_of, ProtoArg, Ticker, UnitsArgs};
use crate::error::Result;
use aptscope_capture::open::{open_with_progress, OpenOptions};
use aptscope_capture::Event;
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::stats::Stats;
use aptscope_dissector::units::UnitsOpts;
use aptscope_replay::parse_duration;
use std::io::{self, Write};

// The options of `stats`.
#[derive(clap::Args)]
pub(crate) struct StatsArgs {
    /// Capture file.
    pub(crate) file: String,
    /// Input format instead of detecting it.
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// One JSON object.
    #[arg(long)]
    pub(crate) json: bool,
    /// Protocol instead of detecting it.
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// Count only the records this display filter matches.
    #[arg(short = 'Y', long = "filter")]
    pub(crate) filter: Option<String>,
    /// Reply timeout for every request (`500ms`, `2s`) instead of the per-message defaults.
    #[arg(long, value_parser = parse_duration)]
    pub(crate) timeout: Option<u64>,
    /// Width of the rate bins (`1s`, `100ms`; plain numbers are seconds).
    #[arg(long, value_parser = parse_bin, default_value = "1s")]
    pub(crate) bin: u64,
    /// USB captures: only the device at BUS:ADDR.
    #[arg(long)]
    pub(crate) usb_device: Option<String>,
    #[command(flatten)]
    pub(crate) units: UnitsArgs,
}

/// The statistics of the capture `a` names.
pub(crate) fn run(a: StatsArgs) -> Result<()> {
    let o = open_opts(a.format.as_deref(), false, a.usb_device.as_deref())?;
    let u = a.units.opts()?;
    stats(
        &a.file,
        o,
        a.json,
        a.proto,
        a.filter.as_deref(),
        a.bin,
        a.timeout,
        u,
    )
}

/// `--bin` of stats: a duration above zero.
fn parse_bin(s: &str) -> Result<u64, String> {
    match parse_duration(s)? {
        0 => Err(format!(
            "`{s}` is no bin width: give one above zero (`1s`, `100ms`, `0.5`)"
        )),
        ns => Ok(ns),
    }
}

#[allow(clippy::too_many_arguments)]
fn stats(
    file: &str,
    opts: OpenOptions,
    as_json: bool,
    proto: ProtoArg,
    filter: Option<&str>,
    bin: u64,
    timeout: Option<u64>,
    units: UnitsOpts,
) -> Result<()> {
    let f = filter.map(compile_filter).transpose()?;
    let (mut reader, format, progress) = open_with_progress(file, opts)?;
    let mut ticker = Ticker::new(progress);
    let mut st = Stats::new(bin);
    let mut dec = Decoder::new(proto_of(proto));
    dec.set_units(units);
    if let Some(t) = timeout {
        dec.set_reply_timeout(t);
    }
    // Counted straight from the typed records: frames, garbage and no-reply records the filter
    // keeps, and the stream records that name the streams.
    let mut each = |rec: &Record<'_>| -> io::Result<()> {
        ticker.tick();
        match rec {
            Record::Stream { .. } => st.add(rec),
            // Problems of the file itself count whatever the filter says: they are not records.
            Record::Input(d) => st.add_file_problem(d.offset, d.kind.name(), &d.to_string()),
            Record::FileDiag { offset, kind, msg } => st.add_file_problem(*offset, kind, msg),
            Record::Apt(_) | Record::Ell(_) | Record::Garbage(_) | Record::NoReply(_)
                if f.as_ref().is_none_or(|f| f.matches(rec)) =>
            {
                st.add(rec)
            }
            _ => {}
        }
        Ok(())
    };
    while let Some(ev) = reader.next_event() {
        if let Event::Diag(d) = &ev {
            fatal(d)?;
        }
        ev.feed(&mut dec, &mut each)?;
    }
    dec.finish(&mut each)?;
    ticker.done();
    // Written, not printed: a closed pipe (`| head`) ends the command quietly.
    let mut out = io::stdout().lock();
    if as_json {
        writeln!(out, "{}", st.to_json())?;
    } else {
        write!(out, "{}", st.to_text())?;
    }
    if proto != ProtoArg::Auto {
        // Forced: counted whatever the input holds.
        return Ok(());
    }
    // Not traffic of these protocols: the command fails with the reason (the tables above are
    // written already).
    let problems = st.file_problems.values().sum();
    aptscope_capture::judge::refuse(&dec, format, problems).map_or(Ok(()), |e| Err(e.into()))
}
