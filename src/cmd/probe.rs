//! `aptscope probe`: survey a connected controller against the spec (see
//! `aptscope_capture::live::probe`).

use crate::error::{CliError, Result};
use aptscope_capture::live::probe::run::{probe, Options};
use aptscope_capture::live::probe::{compare, Report};
use aptscope_capture::open::{create, Format};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::table::{Class, MsgDef};

/// The options of `probe`.
#[derive(clap::Args)]
pub(crate) struct ProbeArgs {
    /// The controller's serial port (or a pseudo-terminal: a simulator's `--pty` link).
    #[arg(long, alias = "device", required_unless_present = "compare")]
    pub(crate) port: Option<String>,
    /// The protocol: an APT controller, or an Elliptec bus (scanned at addresses 0-F).
    #[arg(long, value_enum, default_value_t = ProbeProto::Apt)]
    pub(crate) proto: ProbeProto,
    /// One JSON object (what --compare reads).
    #[arg(long)]
    pub(crate) json: bool,
    /// Every request and its answer, one line each, after the summary.
    #[arg(long, short = 'v')]
    pub(crate) verbose: bool,
    /// Identify the controller and print the plan (every request it would send) without
    /// sending it.
    #[arg(long)]
    pub(crate) dry_run: bool,
    /// Write the whole exchange to this capture (pcapng; pcap or MCAP by the extension).
    #[arg(short = 'w', long)]
    pub(crate) write: Option<String>,
    /// Overwrite the -w file if it exists.
    #[arg(long, requires = "write")]
    pub(crate) force: bool,
    /// Also send the read-only requests the spec does not list for the model (does the device
    /// do more than its list says?).
    #[arg(long)]
    pub(crate) unlisted: bool,
    /// Wait at most this long for any reply (`200ms`, `1s`) instead of the table's timeouts.
    #[arg(long, value_parser = aptscope_replay::parse_duration)]
    pub(crate) timeout: Option<u64>,
    /// Compare this JSON report with another: `--compare A.json B.json`, or with the probe of
    /// --port when one other is given.
    #[arg(long, num_args = 1..=2, value_name = "REPORT.json")]
    pub(crate) compare: Vec<String>,
    /// Exit with status 1 when the report has deviations from the spec.
    #[arg(long)]
    pub(crate) check: bool,
}

/// What `probe --proto` takes.
#[derive(Clone, Copy, clap::ValueEnum)]
pub(crate) enum ProbeProto {
    /// Thorlabs APT (binary).
    Apt,
    /// Elliptec ELLx (ASCII), a bus of up to 16 modules.
    Elliptec,
}

/// Replay's safety rule, applied to the plan on top of the probe's own: a message that starts
/// a move, moves or stops is never sent.
fn moves(m: &MsgDef) -> bool {
    aptscope_replay::safety::starts_move(m)
        || m.class.has(Class::MOTION)
        || m.class.has(Class::STOP)
}

/// Read a JSON report `--compare` names.
fn read_report(path: &str) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Io(std::io::Error::new(e.kind(), format!("{path}: {e}"))))?;
    serde_json::from_str(&text)
        .map_err(|e| CliError::Usage(format!("{path}: not a probe report (--json): {e}")))
}

/// Run the probe `a` describes.
pub(crate) fn run(a: ProbeArgs) -> Result<()> {
    if a.compare.len() == 2 {
        let (x, y) = (read_report(&a.compare[0])?, read_report(&a.compare[1])?);
        print!("{}", compare((&a.compare[0], &x), (&a.compare[1], &y)));
        return Ok(());
    }
    let Some(port) = a.port.as_deref() else {
        return Err(CliError::Usage(
            "give --port, or two reports to --compare".into(),
        ));
    };
    let other = a.compare.first().map(|p| read_report(p)).transpose()?;
    // Created before anything is sent, so a bad path fails before the device is touched.
    let mut out = match &a.write {
        Some(w) => Some(create(w, Format::for_writing(w, None)?, a.force)?),
        None => None,
    };
    let opts = Options {
        unlisted: a.unlisted,
        max_timeout_ms: a
            .timeout
            .map(|ns| u32::try_from(ns / 1_000_000).unwrap_or(u32::MAX).max(1)),
        refuse: Some(moves),
    };
    let proto = match a.proto {
        ProbeProto::Apt => Proto::Apt,
        ProbeProto::Elliptec => Proto::Elliptec,
    };
    let (report, steps) = probe(port, proto, &opts, a.dry_run)?;
    if let Some(w) = out.as_mut() {
        report.write_to(w.as_mut())?;
    }
    if a.dry_run {
        print_plan(&report, &steps);
        return Ok(());
    }
    match (&other, a.json) {
        (Some(o), _) => {
            let me = report.to_json();
            print!("{}", compare((port, &me), (&a.compare[0], o)));
        }
        (None, true) => println!("{}", report.to_json()),
        (None, false) => {
            print!("{}", report.text());
            if a.verbose {
                print!("\n{}", report.detail());
            }
        }
    }
    if report.interrupted {
        eprintln!("aptscope probe: interrupted; the report covers the requests sent so far");
    }
    if a.check && report.deviations().next().is_some() {
        return Err(CliError::Differences);
    }
    Ok(())
}

/// `--dry-run`: the controller and every request the probe would send.
fn print_plan(report: &Report, steps: &[aptscope_capture::live::probe::Step]) {
    print!(
        "{}",
        report
            .text()
            .lines()
            .take(2 + report.units.len())
            .fold(String::new(), |mut s, l| {
                s.push_str(l);
                s.push('\n');
                s
            },)
    );
    println!(
        "plan      {} read-only request(s), one at a time:",
        steps.len()
    );
    for s in steps {
        let hex: Vec<String> = if report.elliptec {
            vec![String::from_utf8_lossy(&s.bytes).into_owned()]
        } else {
            s.bytes.iter().map(|b| format!("{b:02x}")).collect()
        };
        println!(
            "  0x{:02X} {:<34} {:<7} {}",
            s.dst,
            s.label(),
            format!("{} ms", s.timeout_ms),
            hex.join(" ")
        );
    }
}
