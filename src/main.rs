//! `aptscope`: the command line. Parses arguments and calls the libraries.
#![forbid(unsafe_code)]

use aptscope_capture::follow::FollowStop;
use aptscope_capture::info::summarize;
use aptscope_capture::live::serial::Flow;
use aptscope_capture::live::sim::{apt_sim, ell_sim, sim_apt_main, sim_elliptec_main, SimLine};
use aptscope_capture::live::tap::{
    sim_with_view, sniff_main, sniff_with_view, tap_main, tap_with_view, LiveView, SniffOptions,
    TapOptions, TapStats,
};
use aptscope_capture::open::{create, open, open_with_progress, Format, OpenOptions, Progress};
use aptscope_capture::Event;
use aptscope_dissector::apt::{encode_named_report, Addr, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::filter::Filter;
use aptscope_dissector::record::{Decoder, Record};
use aptscope_dissector::stats::Stats;
use aptscope_dissector::table::{Form, MsgDef};
use aptscope_dissector::units::UnitsOpts;
use aptscope_dissector::{json, Table};
use aptscope_replay::{parse_duration, replay_main, ReplayArgs, ReplayOptions};
use clap::{Parser, Subcommand};
use std::io::{self, BufWriter, Write};
use std::process::ExitCode;

mod batch;
mod extcap;
mod shell;

#[derive(Parser)]
#[command(
    name = "aptscope",
    // The commit too, from build.rs: `0.1.0 (a94ef7b 2026-12-02)`.
    version = env!("APTSCOPE_VERSION"),
    about = "Protocol analyser for Thorlabs APT and Elliptec serial traffic"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum SimCmd {
    /// An APT controller.
    Apt {
        /// The controller model, any the spec names (`--list` shows them): kdc101, tdc001,
        /// bsc203 (three bays), kpz101, k10cr1, kim101, tls001 …
        #[arg(long, default_value = "kdc101")]
        model: String,
        /// List the models with their family, bays and channels, and exit.
        #[arg(long)]
        list: bool,
        /// Symlink to the pseudo-terminal.
        #[arg(long, conflicts_with = "port")]
        pty: Option<std::path::PathBuf>,
        /// Serve on this serial port instead (a null-modem cable to the host's port).
        #[arg(long)]
        port: Option<std::path::PathBuf>,
        /// Baud rate on --port.
        #[arg(long, default_value_t = 115_200)]
        baud: u32,
        /// End when the first host program closes the port (by default the simulator serves
        /// one program after another until stopped, as a controller stays on).
        #[arg(long, conflicts_with = "port")]
        once: bool,
        #[command(flatten)]
        view: SimView,
    },
    /// An Elliptec bus.
    Elliptec {
        /// Modules by address: `0:ELL14,1:ELL9`.
        #[arg(long, default_value = "0:ELL14")]
        modules: String,
        /// Symlink to the pseudo-terminal.
        #[arg(long, conflicts_with = "port")]
        pty: Option<std::path::PathBuf>,
        /// Serve on this serial port instead.
        #[arg(long)]
        port: Option<std::path::PathBuf>,
        /// Baud rate on --port.
        #[arg(long, default_value_t = 9_600)]
        baud: u32,
        /// End when the first host program closes the port.
        #[arg(long, conflicts_with = "port")]
        once: bool,
        #[command(flatten)]
        view: SimView,
    },
}

/// `sim … --view`: the simulator's own traffic in the terminal UI.
#[derive(clap::Args)]
struct SimView {
    /// Show the simulator's traffic live in the terminal UI (recorded by a tap in front of
    /// it, to -w or a temporary pcapng whose path is printed on exit); `q` ends both.
    #[arg(long, conflicts_with_all = ["port", "once"])]
    view: bool,
    /// With --view: write the capture here (pcapng, or pcap by the .pcap extension).
    #[arg(short = 'w', long, requires = "view")]
    write: Option<String>,
    /// With --view: overwrite the -w file if it exists.
    #[arg(long, requires = "write")]
    force: bool,
}

/// Physical units of APT motion values (spec section 8), for the commands that decode.
#[derive(clap::Args)]
struct UnitsArgs {
    /// The stage the APT controller drives (`MTS25-Z8`, `Z825`, `DDS220`, `LTS150`…): positions,
    /// velocities and accelerations are also shown in mm (or deg) and mm/s, mm/s2.
    #[arg(long, value_name = "NAME")]
    stage: Option<String>,
    /// Counts (or microsteps) per unit for a stage section 8 does not list: `34554.96/mm`,
    /// `1919.64/deg` (unit mm when left out).
    #[arg(long, value_name = "X[/UNIT]", conflicts_with = "stage")]
    scale: Option<String>,
    /// The controller (a model, `KDC101`, or a family, `dc_servo`, `brushless`, `stepper`,
    /// `stepper_trinamic`), when the capture has no HW_GET_INFO to tell it.
    #[arg(long, value_name = "MODEL")]
    controller: Option<String>,
}

impl UnitsArgs {
    fn opts(&self) -> io::Result<UnitsOpts> {
        UnitsOpts::from_args(
            self.stage.as_deref(),
            self.scale.as_deref(),
            self.controller.as_deref(),
        )
        .map_err(bad)
    }
}

/// Options shared by `tap` and `sniff`.
#[derive(clap::Args)]
struct LiveArgs {
    /// Protocol on the line (sets the default line settings).
    #[arg(long, value_enum, default_value_t = ProtoArg::Apt)]
    proto: ProtoArg,
    /// Baud rate (default 115200 for APT, 9600 for Elliptec).
    #[arg(long)]
    baud: Option<u32>,
    /// Flow control: none, rtscts, xonxoff (default: tap the protocol's, RTS/CTS for APT;
    /// sniff none, as its adapters only receive).
    #[arg(long)]
    flow: Option<String>,
    /// Write the capture here: pcapng, or pcap when it ends in .pcap (another extension is
    /// refused unless --write-format says).
    #[arg(short = 'w', long)]
    write: Option<String>,
    /// Format of the -w file whatever its name: pcapng or pcap.
    #[arg(long, requires = "write")]
    write_format: Option<String>,
    /// Overwrite the capture file if it exists.
    #[arg(long)]
    force: bool,
    /// Wait for a vanished device to come back.
    #[arg(long)]
    reconnect: bool,
    /// Do not print the live timeline.
    #[arg(long)]
    quiet: bool,
    /// Stop after this long (`30s`).
    #[arg(long, value_parser = parse_duration)]
    duration: Option<u64>,
    /// Show the traffic live in the terminal UI instead of the text timeline; the capture (-w,
    /// else a temporary pcapng whose path is printed on exit) is recorded as without it, and
    /// `q` or Ctrl-C in the UI stops the tap.
    #[arg(long, conflicts_with = "quiet")]
    view: bool,
    #[command(flatten)]
    units: UnitsArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ExportArg {
    /// A Wireshark/tshark Lua dissector generated from the tables.
    WiresharkLua,
}

/// Output of `decode`.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ToArg {
    /// One line per record.
    Text,
    /// NDJSON.
    Json,
    /// A Parquet dataset (-o DIR).
    Parquet,
}

#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum ProtoArg {
    Auto,
    Apt,
    Elliptec,
}

#[derive(Subcommand)]
enum Cmd {
    /// Decode captures (any readable format, detected from content): one line per frame, or
    /// NDJSON with --json.
    Decode {
        /// Capture files, or `-` for standard input (the default when it is not a terminal).
        files: Vec<String>,
        /// Input format instead of detecting it (pcap, pcapng, mcap, socat, jpnevulator,
        /// interceptty, xxd, hexdump, hex, raw).
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// Shorthand for --format hex: hex text, any whitespace.
        #[arg(long)]
        hex: bool,
        /// Write NDJSON, one object per frame or garbage record (same as --to json).
        #[arg(long)]
        json: bool,
        /// Output: text (default), json (NDJSON), or parquet (a dataset directory, -o; see
        /// docs/parquet.md).
        #[arg(long, value_enum)]
        to: Option<ToArg>,
        /// The Parquet dataset directory (--to parquet).
        #[arg(short = 'o', long, value_name = "DIR")]
        output: Option<std::path::PathBuf>,
        /// Replace an existing dataset directory.
        #[arg(long)]
        force: bool,
        /// Files decoded at once (default: the number of cores).
        #[arg(short = 'j', long, value_name = "N")]
        jobs: Option<usize>,
        /// Protocol of the stream (default: detected from the first 4 KiB).
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// USB captures: only the device at BUS:ADDR.
        #[arg(long)]
        usb_device: Option<String>,
        /// Display filter: only records it matches (`apt.name ~ "MOT_" && dir == device`).
        #[arg(short = 'Y', long = "filter")]
        filter: Option<String>,
        /// Reply timeout for every request (`500ms`, `2s`) instead of the per-message defaults.
        #[arg(long, value_parser = parse_duration)]
        timeout: Option<u64>,
        /// Follow a capture another program is still writing, like `tail -f`: each record is
        /// printed as its bytes arrive, until interrupted (Ctrl-C). Standard input from a pipe
        /// is followed without it (`dumpcap -w - | aptscope decode -`).
        #[arg(long)]
        follow: bool,
        #[command(flatten)]
        units: UnitsArgs,
    },
    /// Statistics of a capture: counts and bytes per message, address and direction, request
    /// latency (min/median/p99/max), diagnostics by kind, rate over time.
    Stats {
        /// Capture file.
        file: String,
        /// Input format instead of detecting it.
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// One JSON object.
        #[arg(long)]
        json: bool,
        /// Protocol instead of detecting it.
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// Count only the records this display filter matches.
        #[arg(short = 'Y', long = "filter")]
        filter: Option<String>,
        /// Reply timeout for every request (`500ms`, `2s`) instead of the per-message defaults.
        #[arg(long, value_parser = parse_duration)]
        timeout: Option<u64>,
        /// Width of the rate bins (`1s`, `100ms`; plain numbers are seconds).
        #[arg(long, value_parser = parse_bin, default_value = "1s")]
        bin: u64,
        /// USB captures: only the device at BUS:ADDR.
        #[arg(long)]
        usb_device: Option<String>,
        #[command(flatten)]
        units: UnitsArgs,
    },
    /// Browse a capture in the terminal UI: timeline, detail tree, hex, filters, statistics, plots.
    View {
        /// Capture file.
        file: String,
        /// Input format instead of detecting it.
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// Protocol (default: detected from the first 4 KiB).
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// USB captures: only the device at BUS:ADDR.
        #[arg(long)]
        usb_device: Option<String>,
        /// Follow a capture another program (a tap) is still writing, like `tail -f`: new
        /// records appear as the file grows; a cut last block is waited for. `-` (a pipe:
        /// `dumpcap -w - | aptscope view --follow -`) is followed until its writer ends.
        #[arg(long)]
        follow: bool,
        #[command(flatten)]
        units: UnitsArgs,
    },
    /// Simulate a controller on a pseudo-terminal (or a serial port, --port):
    /// `sim apt --model kdc101` or `sim elliptec --modules 0:ELL14,1:ELL9`.
    Sim {
        #[command(subcommand)]
        what: SimCmd,
    },
    /// Man-in-the-middle tap: a pseudo-terminal for the host program, forwarded to the real
    /// port; every chunk timestamped, decoded live, and written to a pcapng.
    Tap {
        /// The real serial port.
        #[arg(long)]
        device: String,
        /// Symlink to create for the host program (else the pseudo-terminal path is printed).
        #[arg(long)]
        link: Option<String>,
        #[command(flatten)]
        live: LiveArgs,
    },
    /// Replay a capture to a port with its timing, as the host (to a device or simulator) or
    /// as the device (to a host program), and compare the replies with the captured ones.
    Replay {
        /// The options the replay takes as given.
        #[command(flatten)]
        args: ReplayArgs,
        /// Protocol (default: detected from the capture).
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// Input format instead of detecting it.
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// Flow control: none, rtscts, xonxoff (default: the protocol's).
        #[arg(long)]
        flow: Option<String>,
    },
    /// Passive sniff of a Y-cable with two receive-only adapters, merged by time.
    Sniff {
        /// Adapter receiving what the host sends.
        #[arg(long)]
        host_tx: String,
        /// Adapter receiving what the device sends.
        #[arg(long)]
        device_tx: String,
        #[command(flatten)]
        live: LiveArgs,
    },
    /// What a capture holds: format, streams, counts per direction, times (like capinfos).
    Info {
        /// Capture file.
        file: String,
        /// Input format instead of detecting it.
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// One JSON object.
        #[arg(long)]
        json: bool,
        /// Protocol instead of detecting it.
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// USB captures: only the device at BUS:ADDR.
        #[arg(long)]
        usb_device: Option<String>,
    },
    /// Convert a capture to pcapng, pcap, MCAP, raw bytes or hex text (by OUT's extension, or
    /// --to), losslessly where the target can carry it.
    Convert {
        /// Input capture.
        input: String,
        /// Output file, or `-` for standard output (with --to).
        output: String,
        /// Input format instead of detecting it.
        #[arg(long, short = 'F')]
        format: Option<String>,
        /// Output format: pcapng, pcap, mcap, raw, hex.
        #[arg(long)]
        to: Option<String>,
        /// Overwrite OUT if it exists.
        #[arg(long)]
        force: bool,
        /// USB captures: only the device at BUS:ADDR.
        #[arg(long)]
        usb_device: Option<String>,
    },
    /// Export aptscope's message tables for other tools (`export wireshark-lua -o aptscope.lua`).
    Export {
        /// What to write.
        #[arg(value_enum)]
        what: ExportArg,
        /// Output file (default: standard output).
        #[arg(short, long)]
        output: Option<String>,
    },
    /// Wireshark capture source (extcap): Wireshark runs it, through a symlink named
    /// `aptscope-extcap` in its personal extcap folder, to list the interfaces and options and
    /// to capture a tap into its FIFO (see docs/wireshark.md).
    Extcap(extcap::ExtcapArgs),
    /// List the message table, or show one message (`messages MOT_MOVE_HOME`, `messages 0x0443`).
    Messages {
        /// A message name or id, or a sub-message name (`SETPOINT`, `la:SETPOINT`): show its
        /// fields, forms, revisions, devices, replies and the spec's examples.
        query: Option<String>,
        /// Protocol: apt, elliptec, or auto (default: both, APT first).
        #[arg(long, value_enum, default_value_t = ProtoArg::Auto)]
        proto: ProtoArg,
        /// NDJSON, one object per message and sub-message, with every field.
        #[arg(long)]
        json: bool,
        /// Show each form's fields.
        #[arg(short, long)]
        verbose: bool,
    },
    /// Build a frame from field values and print it as hex (Elliptec: as text).
    Encode {
        /// Protocol: apt (default) or elliptec (`encode --proto elliptec ADDR CMD field=value…`).
        #[arg(long, value_enum, default_value_t = ProtoArg::Apt)]
        proto: ProtoArg,
        /// Message name (`MOT_MOVE_ABSOLUTE`, `MGMSG_` prefix optional); Elliptec: the address.
        name: String,
        /// Field values: `name=value` (numbers, `0x` hex, enum labels, flags `A|B`); Elliptec:
        /// the command (`ma`) first.
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

/// Copies the options `tap` and `sniff` share into their options struct (two types with the
/// same fields).
macro_rules! live_fields {
    ($o:ident, $live:ident, $proto:ident, $flow:ident) => {
        $o.proto = $proto;
        $o.baud = $live.baud;
        // Without --flow each keeps its own default: the tap the protocol's, the sniff none
        // (its adapters only receive).
        if $flow.is_some() {
            $o.flow = $flow;
        }
        $o.write = $live.write.clone();
        $o.write_format = write_format($live.write_format.as_deref())?;
        $o.force = $live.force;
        $o.reconnect = $live.reconnect;
        $o.quiet = $live.quiet;
        $o.duration = $live.duration.map(std::time::Duration::from_nanos);
        $o.signals = true;
        $o.units = $live.units.opts()?;
    };
}

fn main() -> ExitCode {
    let mut args: Vec<std::ffi::OsString> = std::env::args_os().collect();
    // A symlink `aptscope-extcap` in Wireshark's extcap folder: Wireshark gives only the
    // extcap flags.
    if args.first().is_some_and(|a0| extcap::invoked_as_extcap(a0)) {
        args.insert(1, "extcap".into());
    }
    let cli = Cli::parse_from(args);
    let r = match cli.cmd {
        Cmd::Decode {
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
        } => open_opts(format.as_deref(), hex, usb_device.as_deref()).and_then(|mut o| {
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
                    return Err(bad("--follow prints records as they come: not with --to parquet".into()));
                }
                // Nothing says when another program's writing ends: followed until interrupted.
                o.follow = Some(FollowStop::new());
            }
            let out = match (to, json, output) {
                (Some(ToArg::Parquet), _, Some(dir)) => {
                    aptscope_parquet::prepare_dir(&dir, force)?;
                    batch::Output::Parquet(dir)
                }
                (Some(ToArg::Parquet), _, None) => {
                    return Err(bad("--to parquet writes a directory: name it with -o DIR".into()))
                }
                (_, _, Some(_)) => {
                    return Err(bad(
                        "-o is the Parquet dataset directory (--to parquet); text and NDJSON go                          to standard output"
                            .into(),
                    ))
                }
                (Some(ToArg::Json), _, None) | (None, true, None) => {
                    batch::Output::Lines { json: true }
                }
                (Some(ToArg::Text), true, None) => {
                    return Err(bad("--json and --to text contradict".into()))
                }
                (Some(ToArg::Text), false, None) | (None, false, None) => {
                    batch::Output::Lines { json: false }
                }
            };
            let files = decode_inputs(files)?;
            let jobs = jobs.unwrap_or_else(|| {
                std::thread::available_parallelism().map_or(1, |n| n.get())
            });
            batch::run(batch::Job {
                files: &files,
                open: o,
                proto,
                filter: filter.as_deref(),
                timeout,
                units: u,
                out,
                jobs,
            })
        }),
        Cmd::View {
            file,
            format,
            proto,
            usb_device,
            follow,
            units,
        } => open_opts(format.as_deref(), false, usb_device.as_deref()).and_then(|mut o| {
            // Standard input is followed as it comes, with or without --follow (a pipe ends
            // when its writer does: `dumpcap -w - | aptscope view --follow -`).
            if follow && file != "-" {
                // Nothing says when another program's writing ends: followed until `q`.
                o.follow = Some(FollowStop::new());
            }
            aptscope_tui::run_with(&file, o, proto_of(proto), units.opts()?)
        }),
        Cmd::Sim { what } => match what {
            SimCmd::Apt { list: true, .. } => {
                print!("{}", aptscope_capture::live::sim::model_list());
                Ok(())
            }
            SimCmd::Apt {
                model, pty, view, ..
            } if view.view => {
                apt_sim(&model)
                    .map_err(invalid_input)
                    .and_then(|sim| sim_view(Box::new(sim), Proto::Apt, pty, view))
            }
            SimCmd::Elliptec {
                modules, pty, view, ..
            } if view.view => ell_sim(&modules)
                .map_err(invalid_input)
                .and_then(|sim| sim_view(Box::new(sim), Proto::Elliptec, pty, view)),
            SimCmd::Apt {
                model,
                pty,
                port,
                baud,
                once,
                ..
            } => sim_apt_main(
                &model,
                sim_line(pty.as_deref(), port.as_deref(), baud, once),
            ),
            SimCmd::Elliptec {
                modules,
                pty,
                port,
                baud,
                once,
                ..
            } => sim_elliptec_main(
                &modules,
                sim_line(pty.as_deref(), port.as_deref(), baud, once),
            ),
        },
        Cmd::Extcap(a) => extcap::extcap_main(a),
        Cmd::Tap { device, link, live } => live_opts(&live).and_then(|(proto, flow)| {
            let mut o = TapOptions::new(device, link);
            live_fields!(o, live, proto, flow);
            if live.view {
                let (path, units) = (viewed_file(&mut o.write, "tap"), o.units.clone());
                let r = tap_with_view(o, |v| live_view(v, proto, units));
                return_view(r, &path, "aptscope tap")
            } else {
                tap_main(o).and_then(check_stats)
            }
        }),
        Cmd::Replay {
            args,
            proto,
            format,
            flow,
        } => open_opts(format.as_deref(), false, None).and_then(|open| {
            let flow = match flow {
                None => None,
                Some(f) => Some(Flow::parse(&f).ok_or_else(|| {
                    bad(format!("unknown flow control {f} (none, rtscts, xonxoff)"))
                })?),
            };
            let o = ReplayOptions {
                args,
                open,
                proto: proto_of(proto),
                flow,
            };
            match replay_main(o) {
                Ok(true) => Ok(()),
                Ok(false) => Err(io::Error::other("differences found (--check)")),
                Err(e) => Err(e),
            }
        }),
        Cmd::Sniff {
            host_tx,
            device_tx,
            live,
        } => live_opts(&live).and_then(|(proto, flow)| {
            let mut o = SniffOptions::new(host_tx, device_tx);
            live_fields!(o, live, proto, flow);
            if live.view {
                let (path, units) = (viewed_file(&mut o.write, "sniff"), o.units.clone());
                let r = sniff_with_view(o, |v| live_view(v, proto, units));
                return_view(r, &path, "aptscope sniff")
            } else {
                sniff_main(o).and_then(check_stats)
            }
        }),
        Cmd::Stats {
            file,
            format,
            json,
            proto,
            filter,
            timeout,
            bin,
            usb_device,
            units,
        } => open_opts(format.as_deref(), false, usb_device.as_deref()).and_then(|o| {
            let u = units.opts()?;
            stats(&file, o, json, proto, filter.as_deref(), bin, timeout, u)
        }),
        Cmd::Info {
            file,
            format,
            json,
            proto,
            usb_device,
        } => open_opts(format.as_deref(), false, usb_device.as_deref())
            .and_then(|o| info(&file, o, json, proto)),
        Cmd::Convert {
            input,
            output,
            format,
            to,
            force,
            usb_device,
        } => open_opts(format.as_deref(), false, usb_device.as_deref())
            .and_then(|o| convert(&input, &output, o, to.as_deref(), force)),
        Cmd::Export {
            what: ExportArg::WiresharkLua,
            output,
        } => {
            let lua = aptscope_dissector::wireshark::lua();
            match output.as_deref() {
                None | Some("-") => io::stdout().lock().write_all(lua.as_bytes()),
                Some(path) => std::fs::write(path, lua)
                    .map_err(|e| io::Error::new(e.kind(), format!("{path}: {e}"))),
            }
        }
        Cmd::Messages {
            proto: ProtoArg::Elliptec,
            json,
            verbose,
            query,
        } => match query {
            None => ell_messages(json, verbose),
            Some(_) => Err(bad(
                "messages NAME looks up APT messages; `messages --proto elliptec -v` lists every \
                 Elliptec command with its fields"
                    .into(),
            )),
        },
        Cmd::Messages {
            query,
            json,
            verbose,
            proto,
        } => match query {
            Some(q) => message_page(&q, json),
            None if proto == ProtoArg::Auto => {
                messages(json, verbose).and_then(|()| ell_messages(json, verbose))
            }
            None => messages(json, verbose),
        },
        Cmd::Encode {
            proto: ProtoArg::Elliptec,
            name,
            values,
            dest,
            source,
            form,
            sub,
        } => match (dest, source, form, sub) {
            (None, None, None, None) => ell_encode(&name, &values),
            _ => Err(bad(
                "--dest, --source, --form and --sub are APT options".into()
            )),
        },
        Cmd::Encode {
            name,
            values,
            dest,
            source,
            form,
            sub,
            ..
        } => encode_cmd(
            &name,
            &values,
            dest.as_deref(),
            source.as_deref(),
            form.as_deref(),
            sub.as_deref(),
        ),
        Cmd::Completions { shell } => shell::completions(shell),
        Cmd::Man { command } => shell::man(&command),
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

fn sim_line<'a>(
    pty: Option<&'a std::path::Path>,
    port: Option<&'a std::path::Path>,
    baud: u32,
    once: bool,
) -> SimLine<'a> {
    match port {
        Some(p) => SimLine::Port(p, baud),
        None if once => SimLine::PtyOnce(pty),
        None => SimLine::Pty(pty),
    }
}

fn proto_of(p: ProtoArg) -> Option<Proto> {
    match p {
        ProtoArg::Auto => None,
        ProtoArg::Apt => Some(Proto::Apt),
        ProtoArg::Elliptec => Some(Proto::Elliptec),
    }
}

fn open_opts(format: Option<&str>, hex: bool, usb: Option<&str>) -> io::Result<OpenOptions> {
    let format = match (format, hex) {
        (Some(f), _) => Some(Format::parse(f).ok_or_else(|| {
            bad(format!(
                "unknown format {f} (one of {})",
                Format::NAMES.join(", ")
            ))
        })?),
        (None, true) => Some(Format::Hex),
        (None, false) => None,
    };
    let usb_device = match usb {
        None => None,
        Some(s) => {
            let (b, a) = s
                .split_once(':')
                .ok_or_else(|| bad(format!("--usb-device takes BUS:ADDR, not {s}")))?;
            Some((
                b.parse().map_err(|_| bad(format!("bad bus {b}")))?,
                a.parse().map_err(|_| bad(format!("bad address {a}")))?,
            ))
        }
    };
    Ok(OpenOptions {
        format,
        usb_device,
        follow: None,
    })
}

/// A reader's diagnostic that makes the command fail: the input has nothing of what was asked
/// for (`--usb-device` naming no device of the capture).
fn fatal(d: &aptscope_capture::ReadDiag) -> io::Result<()> {
    if d.kind() == aptscope_capture::usb::NOT_FOUND {
        return Err(bad(d.msg()));
    }
    Ok(())
}

/// The inputs of `decode`: standard input when none is named, unless it is a terminal (a user
/// who forgot the file would wait for nothing).
fn decode_inputs(files: Vec<String>) -> io::Result<Vec<String>> {
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

/// `--write-format` of tap and sniff: pcapng or pcap.
fn write_format(f: Option<&str>) -> io::Result<Option<Format>> {
    match f {
        None => Ok(None),
        Some("pcapng") => Ok(Some(Format::PcapNg)),
        Some("pcap") => Ok(Some(Format::Pcap)),
        Some(other) => Err(bad(format!(
            "--write-format {other}: the tap writes pcapng or pcap"
        ))),
    }
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

fn compile_filter(src: &str) -> io::Result<Filter> {
    Filter::parse(src).map_err(|e| bad(format!("bad filter: {e}\n{}", e.caret(src))))
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
) -> io::Result<()> {
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
    aptscope_capture::judge::refuse(&dec, format, problems).map_or(Ok(()), Err)
}

fn info(file: &str, opts: OpenOptions, as_json: bool, proto: ProtoArg) -> io::Result<()> {
    let (mut reader, _) = open(file, opts)?;
    let i = summarize(reader.as_mut(), proto_of(proto));
    i.file_diags.iter().try_for_each(fatal)?;
    let mut out = io::stdout().lock();
    if as_json {
        writeln!(out, "{}", i.to_json(file))
    } else {
        write!(out, "{}", i.to_text(file))
    }
}

fn convert(
    input: &str,
    output: &str,
    opts: OpenOptions,
    to: Option<&str>,
    force: bool,
) -> io::Result<()> {
    let target = match to {
        Some(t) => Format::parse(t).ok_or_else(|| bad(format!("unknown output format {t}")))?,
        None => Format::from_extension(output).ok_or_else(|| {
            bad(format!(
                "cannot tell the output format from {output}: use --to pcapng|pcap|mcap|raw|hex"
            ))
        })?,
    };
    if output == "-"
        && matches!(target, Format::PcapNg | Format::Pcap | Format::Raw)
        && std::io::IsTerminal::is_terminal(&io::stdout())
    {
        return Err(bad(format!(
            "{} is binary and standard output is a terminal: redirect it (> FILE, | …) or \
             name a file",
            target.name()
        )));
    }
    let (mut reader, from, progress) = open_with_progress(input, opts)?;
    let mut ticker = Ticker::new(progress);
    let mut w = create(output, target, force)?;
    let (mut chunks, mut bytes, mut diags) = (0u64, 0u64, 0u64);
    while let Some(ev) = reader.next_event() {
        ticker.tick();
        match ev {
            Event::Stream(s) => w.stream(&s)?,
            Event::Chunk(c) => {
                chunks += 1;
                bytes += c.bytes.len() as u64;
                w.chunk(&c)?;
            }
            Event::Diag(d) => {
                fatal(&d)?;
                diags += 1;
                eprintln!("aptscope: {input}: {d}");
                w.diag(&d)?;
            }
        }
    }
    w.finish()?;
    ticker.done();
    eprintln!(
        "{input} ({}) -> {output} ({}): {chunks} chunks, {bytes} bytes, {diags} input diagnostics",
        from.name(),
        target.name()
    );
    // Only what this input had that the target dropped.
    for l in w.lost() {
        eprintln!("  {} cannot carry: {l}", target.name());
    }
    Ok(())
}

fn message_page(query: &str, as_json: bool) -> io::Result<()> {
    use aptscope_dissector::listing::{lookup, man_page, Entry};
    let table = Table::global();
    let entries = lookup(table, query).map_err(bad)?;
    let mut out = BufWriter::new(io::stdout().lock());
    let mut s = String::new();
    for e in entries {
        s.clear();
        match (as_json, e) {
            (true, Entry::Msg(m)) => json::msg_def(&mut s, table, m),
            (true, Entry::Sub(x)) => json::sub_def(&mut s, table, x),
            (false, e) => man_page(table, e, &mut s),
        }
        writeln!(out, "{}", s.trim_end())?;
    }
    out.flush()
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
        let forms: Vec<String> = m.forms.iter().map(Form::label).collect();
        let replies: Vec<&str> = table.replies_of(m).iter().map(|r| r.name).collect();
        let reply = if replies.is_empty() {
            String::new()
        } else {
            format!(" → {}", replies.join(","))
        };
        let rev = if m.revs == aptscope_dissector::table::Revs::REV_2025 {
            "  [2025]"
        } else {
            ""
        };
        writeln!(
            out,
            "0x{:04X}  {:<40} {:<4}  {:<10}{reply}{rev}",
            m.id,
            m.name,
            m.dir.as_str(),
            forms.join("|")
        )?;
        if verbose {
            if !m.doc.is_empty() {
                writeln!(out, "        {}", m.doc)?;
            }
            let models = table.models_of(m);
            if !models.is_empty() {
                writeln!(out, "        devices: {}", models.join(" "))?;
            }
            for f in &m.forms {
                let fields: Vec<String> = f
                    .fields
                    .iter()
                    .map(|x| format!("{}:{}", x.name, x.ty.name()))
                    .collect();
                writeln!(out, "        [{}] {}", f.label(), fields.join(" "))?;
            }
        }
    }
    for s in table.subs() {
        let forms: Vec<String> = s.forms.iter().map(Form::label).collect();
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

/// `messages --proto elliptec`: the listing lives in the dissector.
fn ell_messages(as_json: bool, verbose: bool) -> io::Result<()> {
    let mut out = BufWriter::new(io::stdout().lock());
    if as_json {
        for l in aptscope_dissector::ell::listing::json_lines() {
            writeln!(out, "{l}")?;
        }
    } else {
        out.write_all(aptscope_dissector::ell::listing::text(verbose).as_bytes())?;
    }
    out.flush()
}

/// `encode --proto elliptec ADDR CMD field=value…`: the frame as text (escaped CR LF for
/// replies), or as hex when it holds binary data (`C1`/`C2`).
fn ell_encode(addr: &str, args: &[String]) -> io::Result<()> {
    use aptscope_dissector::ell::encode;
    let (cmd, values) = args
        .split_first()
        .ok_or_else(|| bad("usage: encode --proto elliptec ADDR CMD [field=value …]".into()))?;
    let bytes = encode::assignments(values)
        .and_then(|v| encode::encode(addr, cmd, &v))
        .map_err(|e| bad(e.to_string()))?;
    writeln!(io::stdout(), "{}", encode::display(&bytes))
}

/// A progress line on stderr for long jobs, only when stderr is a terminal.
struct Ticker {
    progress: Progress,
    on: bool,
    last: std::time::Instant,
    count: u32,
    shown: bool,
}

impl Ticker {
    fn new(progress: Progress) -> Self {
        use std::io::IsTerminal;
        Ticker {
            progress,
            on: io::stderr().is_terminal(),
            last: std::time::Instant::now(),
            count: 0,
            shown: false,
        }
    }

    fn tick(&mut self) {
        self.count = self.count.wrapping_add(1);
        if !self.on
            || !self.count.is_multiple_of(4096)
            || self.last.elapsed() < std::time::Duration::from_millis(250)
        {
            return;
        }
        self.last = std::time::Instant::now();
        let mb = self
            .progress
            .read
            .load(std::sync::atomic::Ordering::Relaxed) as f64
            / 1e6;
        match self.progress.fraction() {
            Some(f) => eprint!("\r{:5.1}%  {mb:.1} MB ", f * 100.0),
            None => eprint!("\r{mb:.1} MB "),
        }
        self.shown = true;
    }

    fn done(&mut self) {
        if self.shown {
            eprint!("\r{:30}\r", "");
        }
    }
}

fn live_opts(l: &LiveArgs) -> io::Result<(Proto, Option<Flow>)> {
    let proto = proto_of(l.proto).unwrap_or(Proto::Apt);
    let flow = match &l.flow {
        None => None,
        Some(f) => Some(
            Flow::parse(f)
                .ok_or_else(|| bad(format!("unknown flow control {f} (none, rtscts, xonxoff)")))?,
        ),
    };
    Ok((proto, flow))
}

/// The file a live view follows: `write` (-w), else a new temporary pcapng (set into `write`).
fn viewed_file(write: &mut Option<String>, what: &str) -> String {
    write
        .get_or_insert_with(|| {
            let t = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs());
            let name = format!("aptscope-{what}-{t}-{}.pcapng", std::process::id());
            std::env::temp_dir()
                .join(name)
                .to_string_lossy()
                .into_owned()
        })
        .clone()
}

/// The terminal UI on the file a tap is writing (`v`), closing when the tap stops.
fn live_view(v: LiveView<'_>, proto: Proto, units: UnitsOpts) -> io::Result<()> {
    let o = OpenOptions {
        follow: Some(v.written),
        ..OpenOptions::default()
    };
    aptscope_tui::run_live(v.path, v.host, o, Some(proto), units, v.quit)
}

/// After a live view: say where the capture is, and check it holds every forwarded byte.
fn return_view(r: io::Result<TapStats>, path: &str, what: &str) -> io::Result<()> {
    if std::path::Path::new(path).exists() {
        aptscope_capture::note!("{what}: capture in {path}");
    }
    r.and_then(check_stats)
}

/// `sim … --view`: the simulator behind a tap whose host side is `pty` (or the printed
/// pseudo-terminal), the tap's file in the terminal UI.
fn sim_view(
    sim: Box<dyn aptscope_capture::live::sim::Simulator + Send>,
    proto: Proto,
    pty: Option<std::path::PathBuf>,
    view: SimView,
) -> io::Result<()> {
    let link = pty.map(|p| p.to_string_lossy().into_owned());
    let mut o = TapOptions::new(String::new(), link);
    o.proto = proto;
    o.write = view.write;
    o.force = view.force;
    let path = viewed_file(&mut o.write, "sim");
    let r = sim_with_view(sim, o, |v| live_view(v, proto, UnitsOpts::default()));
    return_view(r, &path, "aptscope sim")
}

/// A capture that does not hold every forwarded byte is a failure.
fn check_stats(s: TapStats) -> io::Result<()> {
    if s.file_matches() {
        Ok(())
    } else {
        Err(io::Error::other(
            "the capture file does not hold every forwarded byte (see the counts above)",
        ))
    }
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
    let addr = |s: Option<&str>, default: Addr| -> io::Result<u8> {
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
    writeln!(io::stdout(), "{}", hex.join(" "))
}

/// A simulator that cannot be built from its arguments, as the I/O error the commands return.
fn invalid_input(e: aptscope_capture::live::sim::SimError) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, e)
}
