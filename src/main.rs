//! `aptscope`: the command line. Parses arguments and calls the libraries.
#![forbid(unsafe_code)]

use clap::{Parser, Subcommand};
use std::io;
use std::process::ExitCode;

mod batch;
mod cmd;
mod common;
mod error;
mod extcap;
mod shell;

use error::CliError;

#[derive(Parser)]
#[command(
    name = "aptscope",
    // The commit too, from build.rs: `0.1.0 (a94ef7b 2026-12-02)`.
    version = env!("APTSCOPE_VERSION"),
    about = "Protocol analyser for Thorlabs APT and Elliptec serial traffic",
    after_long_help = shell::exit_status_help()
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Decode captures (any readable format, detected from content): one line per frame, or
    /// NDJSON with --json.
    Decode(cmd::decode::DecodeArgs),
    /// Statistics of a capture: counts and bytes per message, address and direction, request
    /// latency (min/median/p99/max), diagnostics by kind, rate over time.
    Stats(cmd::stats::StatsArgs),
    /// Browse a capture in the terminal UI: timeline, detail tree, hex, filters, statistics, plots.
    View(cmd::view::ViewArgs),
    /// Simulate a controller on a pseudo-terminal (or a serial port, --port):
    /// `sim apt --model kdc101` or `sim elliptec --modules 0:ELL14,1:ELL9`.
    Sim {
        #[command(subcommand)]
        what: cmd::sim::SimCmd,
    },
    /// Man-in-the-middle tap: a pseudo-terminal for the host program, forwarded to the real
    /// port; every chunk timestamped, decoded live, and written to a pcapng.
    Tap(cmd::live::TapArgs),
    /// Replay a capture to a port with its timing, as the host (to a device or simulator) or
    /// as the device (to a host program), and compare the replies with the captured ones.
    Replay(cmd::replay::ReplayCmd),
    /// Survey a connected controller against the spec: identify it, send every read-only
    /// request the spec lists for its model (never a SET or a move), and report what it
    /// answers, with which layout, how fast, and where it differs.
    Probe(cmd::probe::ProbeArgs),
    /// Passive sniff of a Y-cable with two receive-only adapters, merged by time.
    Sniff(cmd::live::SniffArgs),
    /// What a capture holds: format, streams, counts per direction, times (like capinfos).
    Info(cmd::info::InfoArgs),
    /// Convert a capture to pcapng, pcap, MCAP, raw bytes or hex text (by OUT's extension, or
    /// --to), losslessly where the target can carry it.
    Convert(cmd::convert::ConvertArgs),
    /// Export aptscope's message tables for other tools (`export wireshark-lua -o aptscope.lua`).
    Export(cmd::export::ExportArgs),
    /// Wireshark capture source (extcap): Wireshark runs it, through a symlink named
    /// `aptscope-extcap` in its personal extcap folder, to list the interfaces and options and
    /// to capture a tap into its FIFO (see docs/wireshark.md).
    Extcap(extcap::ExtcapArgs),
    /// List the message table, or show one message (`messages MOT_MOVE_HOME`, `messages 0x0443`).
    Messages(cmd::messages::MessagesArgs),
    /// Build a frame from field values and print it as hex (Elliptec: as text).
    Encode(cmd::encode::EncodeArgs),
    /// Print a shell completion script (`source <(aptscope completions bash)`, or save it where
    /// the shell loads completions from).
    Completions {
        /// The shell.
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Print a man page in roff (`aptscope man decode > aptscope-decode.1`; `man -l` shows it).
    Man {
        /// The command it documents (`decode`, `sim apt`); none: aptscope itself.
        command: Vec<String>,
    },
}

fn main() -> ExitCode {
    let mut args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    // A symlink `aptscope-extcap` in Wireshark's extcap folder: Wireshark gives only the
    // extcap flags.
    if args.first().is_some_and(|a0| extcap::invoked_as_extcap(a0)) {
        args.insert(1, "extcap".into());
    }
    let r = match Cli::parse_from(args).cmd {
        Cmd::Decode(a) => cmd::decode::run(a),
        Cmd::Stats(a) => cmd::stats::run(a),
        Cmd::View(a) => cmd::view::run(a),
        Cmd::Probe(a) => cmd::probe::run(a),
        Cmd::Sim { what } => cmd::sim::run(what),
        Cmd::Tap(a) => cmd::live::tap(a),
        Cmd::Replay(a) => cmd::replay::run(a),
        Cmd::Sniff(a) => cmd::live::sniff(a),
        Cmd::Info(a) => cmd::info::run(a),
        Cmd::Convert(a) => cmd::convert::run(a),
        Cmd::Export(a) => cmd::export::run(a),
        Cmd::Extcap(a) => extcap::extcap_main(a).map_err(CliError::from),
        Cmd::Messages(a) => cmd::messages::run(a),
        Cmd::Encode(a) => cmd::encode::run(a),
        Cmd::Completions { shell } => shell::completions(shell).map_err(CliError::from),
        Cmd::Man { command } => shell::man(&command).map_err(CliError::from),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.kind() == io::ErrorKind::BrokenPipe => ExitCode::SUCCESS,
        Err(e) => {
            aptscope_capture::note!("aptscope: {e}");
            ExitCode::FAILURE
        }
    }
}
