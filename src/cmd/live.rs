//! `aptscope tap` and `aptscope sniff`: live captures, with a text timeline or the terminal
//! UI (`--view`); and what `sim --view` shares with them.

use crate::common::{bad, proto_of, ProtoArg, UnitsArgs};
use crate::error::{CliError, Result};
use aptscope_capture::live::error::LiveError;
use aptscope_capture::live::serial::Flow;
use aptscope_capture::live::tap::{
    sniff_main, sniff_with_view, tap_main, tap_with_view, LiveOptions, LiveView, SniffOptions,
    TapOptions, TapStats, ViewAbandoned,
};
use aptscope_capture::open::{Format, OpenOptions};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::units::UnitsOpts;
use aptscope_replay::parse_duration;
use std::io;

/// Options shared by `tap` and `sniff`.
#[derive(clap::Args)]
pub(crate) struct LiveArgs {
    /// Protocol on the line (sets the default line settings).
    #[arg(long, value_enum, default_value_t = ProtoArg::Apt)]
    pub(crate) proto: ProtoArg,
    /// Baud rate (default 115200 for APT, 9600 for Elliptec).
    #[arg(long)]
    pub(crate) baud: Option<u32>,
    /// Flow control: none, rtscts, xonxoff (default: tap the protocol's, RTS/CTS for APT;
    /// sniff none, as its adapters only receive).
    #[arg(long)]
    pub(crate) flow: Option<String>,
    /// Write the capture here: pcapng, or pcap when it ends in .pcap (another extension is
    /// refused unless --write-format says).
    #[arg(short = 'w', long)]
    pub(crate) write: Option<String>,
    /// Format of the -w file whatever its name: pcapng or pcap.
    #[arg(long, requires = "write")]
    pub(crate) write_format: Option<String>,
    /// Overwrite the capture file if it exists.
    #[arg(long)]
    pub(crate) force: bool,
    /// Wait for a vanished device to come back.
    #[arg(long)]
    pub(crate) reconnect: bool,
    /// Do not print the live timeline.
    #[arg(long)]
    pub(crate) quiet: bool,
    /// Stop after this long (`30s`).
    #[arg(long, value_parser = parse_duration)]
    pub(crate) duration: Option<u64>,
    /// Show the traffic live in the terminal UI instead of the text timeline; the capture (-w,
    /// else a temporary pcapng whose path is printed on exit) is recorded as without it, and
    /// `q` or Ctrl-C in the UI stops the tap.
    #[arg(long, conflicts_with = "quiet")]
    pub(crate) view: bool,
    #[command(flatten)]
    pub(crate) units: UnitsArgs,
}

// The options of `tap`.
#[derive(clap::Args)]
pub(crate) struct TapArgs {
    /// The real serial port.
    #[arg(long)]
    pub(crate) device: String,
    /// Symlink to create for the host program (else the pseudo-terminal path is printed).
    #[arg(long)]
    pub(crate) link: Option<String>,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
}

// The options of `sniff`.
#[derive(clap::Args)]
pub(crate) struct SniffArgs {
    /// Adapter receiving what the host sends.
    #[arg(long)]
    pub(crate) host_tx: String,
    /// Adapter receiving what the device sends.
    #[arg(long)]
    pub(crate) device_tx: String,
    #[command(flatten)]
    pub(crate) live: LiveArgs,
}

/// Run a tap.
pub(crate) fn tap(a: TapArgs) -> Result<()> {
    let TapArgs { device, link, live } = a;
    let mut o = TapOptions::new(device, link);
    let proto = live_opts(&live, &mut o.live)?;
    if live.view {
        let (path, units) = (viewed_file(&mut o.live.write, "tap"), o.live.units.clone());
        let r = tap_with_view(o, |v| live_view(v, proto, units), end_abandoned);
        return_view(r, &path, "aptscope tap")
    } else {
        check_stats(tap_main(o))
    }
}

/// Run a sniff.
pub(crate) fn sniff(a: SniffArgs) -> Result<()> {
    let SniffArgs {
        host_tx,
        device_tx,
        live,
    } = a;
    let mut o = SniffOptions::new(host_tx, device_tx);
    let proto = live_opts(&live, &mut o.live)?;
    if live.view {
        let (path, units) = (
            viewed_file(&mut o.live.write, "sniff"),
            o.live.units.clone(),
        );
        let r = sniff_with_view(o, |v| live_view(v, proto, units), end_abandoned);
        return_view(r, &path, "aptscope sniff")
    } else {
        check_stats(sniff_main(o))
    }
}

/// `--write-format` of tap and sniff: pcapng or pcap.
fn write_format(f: Option<&str>) -> Result<Option<Format>> {
    match f {
        None => Ok(None),
        Some("pcapng") => Ok(Some(Format::PcapNg)),
        Some("pcap") => Ok(Some(Format::Pcap)),
        Some(other) => Err(bad(format!(
            "--write-format {other}: the tap writes pcapng or pcap"
        ))),
    }
}

/// The options `tap` and `sniff` share, from their arguments into `o` (whose defaults are the
/// tap's or the sniff's); the protocol.
fn live_opts(l: &LiveArgs, o: &mut LiveOptions) -> Result<Proto> {
    let proto = proto_of(l.proto).unwrap_or(Proto::Apt);
    o.proto = proto;
    o.baud = l.baud;
    // Without --flow each keeps its own default: the tap the protocol's, the sniff none (its
    // adapters only receive).
    if let Some(f) = &l.flow {
        o.flow = Some(
            Flow::parse(f)
                .ok_or_else(|| bad(format!("unknown flow control {f} (none, rtscts, xonxoff)")))?,
        );
    }
    o.write = l.write.clone();
    o.write_format = write_format(l.write_format.as_deref())?;
    o.force = l.force;
    o.reconnect = l.reconnect;
    o.quiet = l.quiet;
    o.duration = l.duration.map(std::time::Duration::from_nanos);
    o.signals = true;
    o.units = l.units.opts()?;
    Ok(proto)
}

/// The file a live view follows: `write` (-w), else a new temporary pcapng (set into `write`).
pub(crate) fn viewed_file(write: &mut Option<String>, what: &str) -> String {
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
pub(crate) fn live_view(v: LiveView<'_>, proto: Proto, units: UnitsOpts) -> io::Result<()> {
    let o = OpenOptions {
        follow: Some(v.written),
        ..OpenOptions::default()
    };
    let source = aptscope_tui::Source::File {
        path: v.path,
        opts: o,
        proto: Some(proto),
        units,
    };
    let options = aptscope_tui::Options {
        note: v.host,
        quit: Some(v.quit),
    };
    aptscope_tui::run(source, options)
}

/// A live view whose terminal has gone never returns: the capture is complete (and said so),
/// end the process with its verdict.
pub(crate) fn end_abandoned(a: ViewAbandoned) -> ! {
    std::process::exit(a.exit_code())
}

/// After a live view: say where the capture is, and check it holds every forwarded byte.
pub(crate) fn return_view(r: Result<TapStats, LiveError>, path: &str, what: &str) -> Result<()> {
    if std::path::Path::new(path).exists() {
        aptscope_capture::note!("{what}: capture in {path}");
    }
    check_stats(r)
}

/// A capture that does not hold every forwarded byte is a failure.
fn check_stats(r: Result<TapStats, LiveError>) -> Result<()> {
    if r?.file_matches() {
        Ok(())
    } else {
        Err(CliError::CaptureIncomplete)
    }
}
