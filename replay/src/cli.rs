//! `aptscope replay`: load, select, check safety, run as host or device, report.

use crate::device::{run_device, DeviceOptions, Responder};
use crate::host::{run_host, HostOptions};
use crate::port::Link;
use crate::safety::{is_motion, is_pseudo_terminal};
use crate::script::{host_schedule, Bound, Script, Selection, Side, Timing};
use aptscope_capture::live::serial::{Flow, LineSettings};
use aptscope_capture::live::sim::termination_signals;
use aptscope_capture::open::{create, Format, OpenOptions};
use aptscope_capture::Writer;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::filter::Filter;
use serde_json::json;
use std::collections::BTreeMap;
use std::io::{self, BufRead, IsTerminal, Write};
use std::path::Path;

/// Which side of the capture to play.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Role {
    /// Send the host's messages to a device.
    #[default]
    Host,
    /// Answer a host program as the captured device did.
    Device,
}

/// The options of `aptscope replay` that are taken as given (the command line flattens them in,
/// `#[command(flatten)]`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ReplayArgs {
    /// The capture (any readable format).
    pub file: String,
    /// Serial port to talk on (a simulator's or a tap's pseudo-terminal works too).
    #[arg(long)]
    pub port: Option<String>,
    /// As device: create a pseudo-terminal for the host program, symlinked here.
    #[arg(long)]
    pub pty: Option<String>,
    /// Which side of the capture to play.
    #[arg(long = "as", value_enum, default_value_t = Role::Host)]
    pub role: Role,
    /// Baud rate (default 115200 for APT, 9600 for Elliptec).
    #[arg(long)]
    pub baud: Option<u32>,
    /// Time factor: 2.0 replays twice as fast.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Ignore the captured gaps.
    #[arg(long)]
    pub asap: bool,
    /// Send each message only after the replies its captured request got (or a timeout).
    #[arg(long)]
    pub wait_replies: bool,
    /// How much longer than captured a reply may take before it is missing (default: per
    /// message, as pairing: 2 s, 120 s for moves and homing).
    #[arg(long = "reply-timeout", value_name = "REPLY_TIMEOUT", value_parser = parse_duration)]
    pub reply_timeout_ns: Option<u64>,
    /// Replay only the messages this display filter accepts (host messages as host,
    /// device messages as device).
    #[arg(short = 'Y', long)]
    pub filter: Option<String>,
    /// From this record number or time (`12`, `2.5s`).
    #[arg(long)]
    pub from: Option<String>,
    /// Up to this record number or time.
    #[arg(long)]
    pub to: Option<String>,
    /// Replay the selection this many times.
    #[arg(long = "loop", default_value_t = 1)]
    pub loops: u32,
    /// Stream to replay, when the capture has several.
    #[arg(long)]
    pub stream: Option<u32>,
    /// Record the session (both directions) here; format from the extension, else pcapng.
    #[arg(short = 'w', long)]
    pub write: Option<String>,
    /// Overwrite the recording if it exists.
    #[arg(long)]
    pub force: bool,
    /// NDJSON timeline and a JSON report.
    #[arg(long)]
    pub json: bool,
    /// Exit with 1 when replies differ from the capture.
    #[arg(long)]
    pub check: bool,
    /// Do not compare this field (repeatable): `serial_number`, `src`.
    #[arg(long)]
    pub ignore: Vec<String>,
    /// Count latency changes beyond this as differences.
    #[arg(long = "latency-tolerance", value_name = "LATENCY_TOLERANCE", value_parser = parse_duration)]
    pub latency_tolerance_ns: Option<u64>,
    /// Print what would be sent and when; send nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Do not ask before motion commands go to a real port.
    #[arg(long)]
    pub yes: bool,
    /// On Ctrl-C, send MOT_MOVE_STOP to channels the replay left moving.
    #[arg(long)]
    pub stop_on_abort: bool,
    /// Do not print the live timeline.
    #[arg(long)]
    pub quiet: bool,
    /// As device: stop after this long.
    #[arg(long = "duration", value_name = "DURATION", value_parser = parse_duration)]
    pub duration_ns: Option<u64>,
}

/// Everything `aptscope replay` takes: the arguments as given, and those the command line
/// interprets (they are shared with other commands).
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// The options taken as given.
    pub args: ReplayArgs,
    /// How to open the capture.
    pub open: OpenOptions,
    /// Force the protocol.
    pub proto: Option<Proto>,
    /// Flow control override.
    pub flow: Option<Flow>,
}

/// A duration (`500ms`, `2s`, `1.5s`, `200us`, `2min`, or plain seconds) in ns.
pub fn parse_duration(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let split = s.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("`{s}` is not a duration (500ms, 2s)"))?;
    let scale = match unit {
        "" | "s" => 1e9,
        "ms" => 1e6,
        "us" => 1e3,
        "ns" => 1.0,
        "min" => 60e9,
        u => return Err(format!("unknown unit `{u}` (ns, us, ms, s, min)")),
    };
    if !(v.is_finite() && v >= 0.0) {
        return Err(format!("`{s}` is not a duration"));
    }
    Ok((v * scale) as u64)
}

fn bad(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

/// `--filter`, compiled (it is read on each record as the capture loads).
fn filter(o: &ReplayOptions) -> io::Result<Option<Filter>> {
    o.args
        .filter
        .as_deref()
        .map(|f| Filter::parse(f).map_err(|e| bad(format!("bad filter: {e}\n{}", e.caret(f)))))
        .transpose()
}

fn selection(o: &ReplayOptions, script: &Script) -> io::Result<Selection> {
    let bound = |s: &Option<String>| -> io::Result<Option<Bound>> {
        s.as_deref().map(Bound::parse).transpose().map_err(bad)
    };
    let sel = Selection {
        from: bound(&o.args.from)?,
        to: bound(&o.args.to)?,
        stream: o.args.stream,
    };
    sel.check_streams(script).map_err(bad)?;
    sel.check_range(script).map_err(bad)?;
    if !(o.args.speed.is_finite() && o.args.speed > 0.0) {
        return Err(bad(format!(
            "--speed {}: give a factor above 0 (2 = twice as fast, 0.5 = half; --asap for no waits)",
            o.args.speed
        )));
    }
    Ok(sel)
}

fn secs(ns: u64) -> String {
    format!("{:.6}", ns as f64 / 1e9)
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `--dry-run`: what would be sent, when.
fn dry_run(
    o: &ReplayOptions,
    script: &Script,
    sel: &Selection,
    out: &mut dyn Write,
) -> io::Result<()> {
    match o.args.role {
        Role::Host => {
            let plan = host_schedule(script, sel, timing(o, script), o.args.loops);
            for s in &plan {
                let m = &script.msgs[s.idx];
                let replies: Vec<String> = script
                    .replies_to(s.idx)
                    .iter()
                    .map(|&r| script.msgs[r].label())
                    .collect();
                if o.args.json {
                    let v = json!({"type": "send", "at_s": s.at_ns as f64 / 1e9, "pass": s.lap + 1,
                        "n": m.n, "name": m.name, "label": m.label(), "raw": hex(&m.raw).replace(' ', ""),
                        "motion": is_motion(m), "expect": replies});
                    writeln!(out, "{v}")?;
                } else {
                    let pass = if o.args.loops > 1 {
                        format!(" [pass {}]", s.lap + 1)
                    } else {
                        String::new()
                    };
                    let expect = if replies.is_empty() {
                        String::new()
                    } else {
                        format!("  → {}", replies.join(", "))
                    };
                    writeln!(
                        out,
                        "+{:>12} s  #{:<6} {}{}{}  [{}]",
                        secs(s.at_ns),
                        m.n,
                        m.label(),
                        pass,
                        expect,
                        hex(&m.raw)
                    )?;
                }
            }
            let motion = plan
                .iter()
                .filter(|s| is_motion(&script.msgs[s.idx]))
                .count();
            if !o.args.json {
                writeln!(
                    out,
                    "# dry run: {} messages to send ({motion} of them motion commands), nothing sent",
                    plan.len()
                )?;
            }
        }
        Role::Device => {
            let mut r = Responder::new(script, sel, o.args.speed);
            for (d, i) in r.prelude() {
                let m = &script.msgs[i];
                writeln!(out, "at start +{} s: {}", secs(d), m.label())?;
            }
            for m in script.msgs.iter().filter(|m| m.side == Side::Host) {
                let a = r.respond(m);
                let answers: Vec<String> = a
                    .out
                    .iter()
                    .map(|&(d, i)| {
                        format!("{} (+{:.1} ms)", script.msgs[i].label(), d as f64 / 1e6)
                    })
                    .collect();
                if o.args.json {
                    let v = json!({"type": "answer", "n": m.n, "request": m.label(), "answers": answers});
                    writeln!(out, "{v}")?;
                } else {
                    writeln!(
                        out,
                        "#{:<6} {} → {}",
                        m.n,
                        m.label(),
                        if answers.is_empty() {
                            "(nothing)".to_string()
                        } else {
                            answers.join(", ")
                        }
                    )?;
                }
            }
        }
    }
    Ok(())
}

fn timing(o: &ReplayOptions, script: &Script) -> Timing {
    Timing {
        speed: if o.args.speed > 0.0 {
            o.args.speed
        } else {
            1.0
        },
        asap: o.args.asap || !script.has_times(),
    }
}

/// Ask before motion commands go to a real port. `Ok(false)`: the user said no.
fn confirm(port: &str, motion: &BTreeMap<String, usize>) -> io::Result<bool> {
    let list: Vec<String> = motion.iter().map(|(n, c)| format!("{n} ×{c}")).collect();
    let what = format!(
        "{} is a real port and the replay sends motion commands: {}",
        port,
        list.join(", ")
    );
    let stdin = io::stdin();
    if !stdin.is_terminal() {
        return Err(bad(format!("{what}; give --yes to send them")));
    }
    eprint!("{what}.\nSend them? [y/N] ");
    io::stderr().flush()?;
    let mut line = String::new();
    stdin.lock().read_line(&mut line)?;
    Ok(matches!(line.trim(), "y" | "Y" | "yes" | "YES" | "Yes"))
}

/// Run `aptscope replay`. `Ok(false)` when `--check` found differences (or the user declined).
pub fn replay_main(o: ReplayOptions) -> io::Result<bool> {
    let script = Script::load(&o.args.file, o.open, o.proto, filter(&o)?)?;
    let sel = selection(&o, &script)?;
    let (hosts, devs) = script.msgs.iter().fold((0, 0), |(h, d), m| match m.side {
        Side::Host => (h + 1, d),
        Side::Device => (h, d + 1),
    });
    aptscope_capture::note!(
        "# {} ({}, {}): {} messages, {hosts} from the host, {devs} from the device{}",
        o.args.file,
        script.format,
        script.proto.name(),
        script.msgs.len(),
        if script.has_times() {
            ""
        } else {
            "; no times: sending as fast as replies allow"
        }
    );
    for n in script.notes.iter().take(10) {
        aptscope_capture::note!("# capture: {n}");
    }
    if script.notes.len() > 10 {
        aptscope_capture::note!(
            "# capture: … and {} more notes (aptscope decode shows them)",
            script.notes.len() - 10
        );
    }
    let stdout = io::stdout();
    let mut out = stdout.lock();
    if o.args.dry_run {
        dry_run(&o, &script, &sel, &mut out)?;
        return Ok(true);
    }
    let line = LineSettings::for_proto(script.proto, o.args.baud, o.flow);
    let plan = host_schedule(&script, &sel, timing(&o, &script), o.args.loops);
    if o.args.role == Role::Host {
        let port = o
            .args
            .port
            .as_deref()
            .ok_or_else(|| bad("--as host needs --port DEV".into()))?;
        // What is wrong with the port comes before any question about sending to it.
        aptscope_capture::live::serial::check_port(port)?;
        if !o.args.yes && !is_pseudo_terminal(Path::new(port)) {
            let mut motion: BTreeMap<String, usize> = BTreeMap::new();
            for s in &plan {
                let m = &script.msgs[s.idx];
                if is_motion(m) {
                    *motion.entry(m.name.clone()).or_default() += 1;
                }
            }
            if !motion.is_empty() && !confirm(port, &motion)? {
                aptscope_capture::note!("# nothing sent");
                return Ok(false);
            }
        }
    }
    // Signals are received through a descriptor: block them before any thread starts.
    let sigs = termination_signals()?;
    let mut abort = || sigs.take();
    let mut link = match (o.args.role, &o.args.port, &o.args.pty) {
        (_, Some(p), None) => Link::open_port(Path::new(p), line)?,
        (Role::Device, None, pty) => {
            let (l, path) = Link::open_pty(pty.as_deref().map(Path::new))?;
            match pty {
                Some(p) => aptscope_capture::note!("# {p} -> {}", path.display()),
                None => aptscope_capture::note!("# {}", path.display()),
            }
            l
        }
        (Role::Host, None, _) => return Err(bad("--as host needs --port DEV".into())),
        (_, Some(_), Some(_)) => return Err(bad("give --port or --pty, not both".into())),
    };
    let mut writer: Option<Box<dyn Writer>> = match &o.args.write {
        Some(w) => Some(create(w, Format::for_writing(w, None)?, o.args.force)?),
        None => None,
    };
    let rec = writer.as_mut().map(|w| &mut **w as &mut dyn Writer);
    let display = !o.args.quiet;
    let mut show = |l: &str| {
        let _ = writeln!(out, "{l}");
    };
    match o.args.role {
        Role::Host => {
            let port = o.args.port.clone().unwrap_or_default();
            aptscope_capture::note!(
                "# replaying {} messages to {port} as the host ({line}{})",
                plan.len(),
                if o.args.wait_replies {
                    ", waiting for replies"
                } else {
                    ""
                }
            );
            let opts = HostOptions {
                timing: timing(&o, &script),
                loops: o.args.loops,
                wait_replies: o.args.wait_replies || !script.has_times(),
                reply_timeout_ns: o.args.reply_timeout_ns,
                stop_on_abort: o.args.stop_on_abort,
                ignore: o.args.ignore.clone(),
                display,
                json: o.args.json,
                say_waits: !o.args.quiet,
            };
            let r = run_host(&script, &sel, &opts, &mut link, rec, &mut show, &mut abort)?;
            drop(link);
            let fails = r.report.failures(o.args.latency_tolerance_ns);
            let mut out = io::stdout().lock();
            if o.args.json {
                let mut v = r.report.json(o.args.latency_tolerance_ns);
                v["type"] = json!("replay");
                v["mode"] = json!("host");
                v["planned"] = json!(r.planned);
                v["sent"] = json!(r.sent);
                v["duration_s"] = json!(r.duration_ns as f64 / 1e9);
                v["timing"] = r.timing.json();
                v["aborted"] = json!(r.aborted);
                v["gone"] = json!(r.gone);
                v["stops"] = json!(r.stops);
                v["notes"] = json!(r.notes);
                v["record_error"] = json!(r.record_error);
                writeln!(out, "{v}")?;
            } else {
                write!(out, "{}", r.report.text(o.args.latency_tolerance_ns))?;
                writeln!(
                    out,
                    "# sent {} of {} messages in {:.3} s; {}",
                    r.sent,
                    r.planned,
                    r.duration_ns as f64 / 1e9,
                    r.timing.summary()
                )?;
                // Unanswered requests are in the report already.
                for n in r.notes.iter().filter(|n| !n.contains("no_reply")) {
                    writeln!(out, "# observed: {n}")?;
                }
                if let Some(a) = &r.aborted {
                    writeln!(out, "# aborted: {a}")?;
                }
                for s in &r.stops {
                    writeln!(out, "# sent on abort: {s}")?;
                }
                if let Some(e) = &r.record_error {
                    writeln!(out, "# recording failed: {e}")?;
                }
                writeln!(
                    out,
                    "# {}",
                    if fails == 0 {
                        "no differences".to_string()
                    } else {
                        format!("{fails} differences")
                    }
                )?;
            }
            if let Some(g) = &r.gone {
                return Err(io::Error::other(format!(
                    "the device went away during the replay: {g}"
                )));
            }
            Ok(!(o.args.check && fails > 0))
        }
        Role::Device => {
            aptscope_capture::note!("# answering as the captured device ({line}); Ctrl-C to stop");
            let opts = DeviceOptions {
                speed: if o.args.speed > 0.0 {
                    o.args.speed
                } else {
                    1.0
                },
                duration_ns: o.args.duration_ns,
                display,
                json: o.args.json,
            };
            let r = run_device(&script, &sel, &opts, &mut link, rec, &mut show, &mut abort)?;
            drop(link);
            let mut out = io::stdout().lock();
            if o.args.json {
                let mut v = r.json();
                v["type"] = json!("replay");
                v["mode"] = json!("device");
                v["gone"] = json!(r.gone);
                v["aborted"] = json!(r.aborted);
                v["record_error"] = json!(r.record_error);
                writeln!(out, "{v}")?;
            } else {
                write!(out, "{}", r.text())?;
                if let Some(g) = &r.gone {
                    writeln!(out, "# the host went away: {g}")?;
                }
                if let Some(e) = &r.record_error {
                    writeln!(out, "# recording failed: {e}")?;
                }
            }
            Ok(!o.args.check || r.unmatched.is_empty())
        }
    }
}
