//! `aptscope decode`: captures to text, NDJSON or a Parquet dataset.

use crate::batch;
use crate::common::{bad, open_opts, ProtoArg, UnitsArgs};
use crate::error::Result;
use aptscope_capture::follow::FollowStop;
use aptscope_replay::parse_duration;
use std::io;

// The options of `decode`.
#[derive(clap::Args)]
pub(crate) struct DecodeArgs {
    /// Capture files, or `-` for standard input (the default when it is not a terminal).
    pub(crate) files: Vec<String>,
    /// Input format instead of detecting it (pcap, pcapng, mcap, socat, jpnevulator,
    /// interceptty, xxd, hexdump, hex, raw).
    #[arg(long, short = 'F')]
    pub(crate) format: Option<String>,
    /// Shorthand for --format hex: hex text, any whitespace.
    #[arg(long)]
    pub(crate) hex: bool,
    /// Write NDJSON, one object per frame or garbage record (same as --to json).
    #[arg(long)]
    pub(crate) json: bool,
    /// Output: text (default), json (NDJSON), or parquet (a dataset directory, -o; see
    /// docs/parquet.md).
    #[arg(long, value_enum)]
    pub(crate) to: Option<ToArg>,
    /// The Parquet dataset directory (--to parquet).
    #[arg(short = 'o', long, value_name = "DIR")]
    pub(crate) output: Option<std::path::PathBuf>,
    /// Replace an existing dataset directory.
    #[arg(long)]
    pub(crate) force: bool,
    /// Threads (default: the number of cores): files decoded at once; fewer files than N
    /// render their lines on the spare ones (same output).
    #[arg(short = 'j', long, value_name = "N")]
    pub(crate) jobs: Option<usize>,
    /// Protocol of the stream (default: detected from the first 4 KiB).
    #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
    pub(crate) proto: ProtoArg,
    /// USB captures: only the device at BUS:ADDR.
    #[arg(long)]
    pub(crate) usb_device: Option<String>,
    /// Display filter: only records it matches (`apt.name ~ "MOT_" && dir == device`).
    #[arg(short = 'Y', long = "filter")]
    pub(crate) filter: Option<String>,
    /// Reply timeout for every request (`500ms`, `2s`) instead of the per-message defaults.
    #[arg(long, value_parser = parse_duration)]
    pub(crate) timeout: Option<u64>,
    /// Follow a capture another program is still writing, like `tail -f`: each record is
    /// printed as its bytes arrive, until interrupted (Ctrl-C). Standard input from a pipe
    /// is followed without it (`dumpcap -w - | aptscope decode -`).
    #[arg(long)]
    pub(crate) follow: bool,
    #[command(flatten)]
    pub(crate) units: UnitsArgs,
}

/// Output of `decode`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ToArg {
    /// One line per record.
    Text,
    /// NDJSON.
    Json,
    /// A Parquet dataset (-o DIR).
    Parquet,
}

/// Decode the files `a` names.
pub(crate) fn run(a: DecodeArgs) -> Result<()> {
    let DecodeArgs {
        files,
        format,
        hex,
        json,
        to,
        output,
        force,
        jobs,
        proto,
        usb_device,
        filter,
        timeout,
        follow,
        units,
    } = a;
    let mut o = open_opts(format.as_deref(), hex, usb_device.as_deref())?;
    let u = units.opts()?;
    if follow {
        if files.len() != 1 || files[0] == "-" {
            return Err(bad(
                "--follow follows one capture file (standard input from a pipe is \
                     followed without it)"
                    .into(),
            ));
        }
        if to == Some(ToArg::Parquet) {
            return Err(bad(
                "--follow prints records as they come: not with --to parquet".into(),
            ));
        }
        // Nothing says when another program's writing ends: followed until interrupted.
        o.follow = Some(FollowStop::new());
    }
    let out = match (to, json, output) {
        (Some(ToArg::Parquet), _, Some(dir)) => {
            aptscope_parquet::prepare_dir(&dir, force)?;
            aptscope_parquet::settle_allocator();
            batch::Output::Parquet(dir)
        }
        (Some(ToArg::Parquet), _, None) => {
            return Err(bad(
                "--to parquet writes a directory: name it with -o DIR".into()
            ))
        }
        (_, _, Some(_)) => {
            return Err(bad(
                "-o is the Parquet dataset directory (--to parquet); text and NDJSON go to \
                 standard output"
                    .into(),
            ))
        }
        (Some(ToArg::Json), _, None) | (None, true, None) => batch::Output::Lines { json: true },
        (Some(ToArg::Text), true, None) => {
            return Err(bad("--json and --to text contradict".into()))
        }
        (Some(ToArg::Text), false, None) | (None, false, None) => {
            batch::Output::Lines { json: false }
        }
    };
    let files = decode_inputs(files)?;
    let jobs = jobs.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    Ok(batch::run(batch::Job {
        files: &files,
        open: o,
        proto,
        filter: filter.as_deref(),
        timeout,
        units: u,
        out,
        jobs,
    })?)
}

/// The inputs of `decode`: standard input when none is named, unless it is a terminal (a user
/// who forgot the file would wait for nothing).
fn decode_inputs(files: Vec<String>) -> Result<Vec<String>> {
    use std::io::IsTerminal;
    if !files.is_empty() {
        return Ok(files);
    }
    if io::stdin().is_terminal() {
        return Err(bad(
            "no capture given: aptscope decode FILE… (`-` reads standard input, \
             e.g. hex typed or pasted, ended by Ctrl-D); aptscope decode --help for more"
                .into(),
        ));
    }
    Ok(vec!["-".into()])
}
