//! `aptscope replay`: load, select, check safety, run as host or device, report.

use crate::device::{run_device, DeviceOptions, Responder};
use crate::host::{run_host, HostOptions};
use crate::port::Link;
use crate::safety::{is_motion, is_pseudo_terminal};
use crate::script::{host_schedule, Bound, Script, Selection, Side, Timing};
use aptscope_capture::live::sim::termination_signals;
use aptscope_capture::live::serial::{Flow, LineSettings};
use aptscope_capture::open::{create, Format, OpenOptions};
use aptscope_capture::Writer;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::filter::Filter;
use serde_json::json;
use std::collections::BTreeMap;
use std::io::{self, BufRead, IsTerminal, Write};
use std::path::Path;

/// Which side of the capture to play.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Role {
    /// Send the host's messages to a device.
    #[default]
    Host,
    /// Answer a host program as the captured device did.
    Device,
}

/// Everything `aptscope replay` takes.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    /// The capture.
    pub file: String,
    /// How to open it.
    pub open: OpenOptions,
    /// Force the protocol.
    pub proto: Option<Proto>,
    /// The serial port to talk on.
    pub port: Option<String>,
    /// As device: a new pseudo-terminal linked here, for the host program.
    pub pty: Option<String>,
    /// Host or device.
    pub role: Role,
    /// Baud rate override.
    pub baud: Option<u32>,
    /// Flow control override.
    pub flow: Option<Flow>,
    /// Speed factor (0 or less: 1).
    pub speed: f64,
    /// Ignore the captured gaps.
    pub asap: bool,
    /// Send each message after the previous one's replies.
    pub wait_replies: bool,
    /// Extra time a reply may take before it is missing, ns (`None`: per message, as
    /// pairing times requests out).
    pub reply_timeout_ns: Option<u64>,
    /// Display filter selecting the messages to send.
    pub filter: Option<String>,
    /// Range start (record or time).
    pub from: Option<String>,
    /// Range end.
    pub to: Option<String>,
    /// Passes.
    pub loops: u32,
    /// Stream to replay.
    pub stream: Option<u32>,
    /// Record the session here.
    pub write: Option<String>,
    /// Overwrite it.
    pub force: bool,
    /// NDJSON timeline and a JSON report.
    pub json: bool,
    /// Fail (exit 1) on differences.
    pub check: bool,
    /// Fields not compared.
    pub ignore: Vec<String>,
    /// Latency changes beyond this are differences, ns.
    pub latency_tolerance_ns: Option<u64>,
    /// Only print what would be sent.
    pub dry_run: bool,
    /// Do not ask before motion commands go to a real port.
    pub yes: bool,
    /// On abort, stop channels left moving.
    pub stop_on_abort: bool,
    /// No live timeline.
    pub quiet: bool,
    /// As device: stop after this long, ns.
    pub duration_ns: Option<u64>,
}

fn bad(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

fn selection(o: &ReplayOptions, script: &Script) -> io::Result<Selection> {
    let filter = match &o.filter {
        Some(f) => {
            Some(Filter::parse(f).map_err(|e| bad(format!("bad filter: {e}\n{}", e.caret(f))))?)
        }
        None => None,
    };
    let bound = |s: &Option<String>| -> io::Result<Option<Bound>> {
        s.as_deref().map(Bound::parse).transpose().map_err(bad)
    };
    let sel = Selection {
        filter,
        from: bound(&o.from)?,
        to: bound(&o.to)?,
        stream: o.stream,
    };
    sel.check_streams(script).map_err(bad)?;
    sel.check_range(script).map_err(bad)?;
    if !(o.speed.is_finite() && o.speed > 0.0) {
        return Err(bad(format!(
            "--speed {}: give a factor above 0 (2 = twice as fast, 0.5 = half; --asap for no waits)",
            o.speed
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
    match o.role {
        Role::Host => {
            let plan = host_schedule(script, sel, timing(o, script), o.loops);
            for s in &plan {
                let m = &script.msgs[s.idx];
                let replies: Vec<String> = script
                    .replies_to(s.idx)
                    .iter()
                    .map(|&r| script.msgs[r].label())
                    .collect();
                if o.json {
                    let v = json!({"type": "send", "at_s": s.at_ns as f64 / 1e9, "pass": s.lap + 1,
                        "n": m.n, "name": m.name, "label": m.label(), "raw": hex(&m.raw).replace(' ', ""),
                        "motion": is_motion(m), "expect": replies});
                    writeln!(out, "{v}")?;
                } else {
                    let pass = if o.loops > 1 {
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
            if !o.json {
                writeln!(
                    out,
                    "# dry run: {} messages to send ({motion} of them motion commands), nothing sent",
                    plan.len()
                )?;
            }
        }
        Role::Device => {
            let mut r = Responder::new(script, sel, o.speed);
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
                if o.json {
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
        speed: if o.speed > 0.0 { o.speed } else { 1.0 },
        asap: o.asap || !script.has_times(),
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
    let script = Script::load(&o.file, o.open, o.proto)?;
    let sel = selection(&o, &script)?;
    let (hosts, devs) = script.msgs.iter().fold((0, 0), |(h, d), m| match m.side {
        Side::Host => (h + 1, d),
        Side::Device => (h, d + 1),
    });
    aptscope_capture::note!(
        "# {} ({}, {}): {} messages, {hosts} from the host, {devs} from the device{}",
        o.file,
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
    if o.dry_run {
        dry_run(&o, &script, &sel, &mut out)?;
        return Ok(true);
    }
    let line = LineSettings::for_proto(script.proto, o.baud, o.flow);
    let plan = host_schedule(&script, &sel, timing(&o, &script), o.loops);
    if o.role == Role::Host {
        let port = o
            .port
            .as_deref()
            .ok_or_else(|| bad("--as host needs --port DEV".into()))?;
        // What is wrong with the port comes before any question about sending to it.
        aptscope_capture::live::serial::check_port(port)?;
        if !o.yes && !is_pseudo_terminal(Path::new(port)) {
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
    let mut abort = || -> Option<String> {
        match sigs.read_signal() {
            Ok(Some(s)) => Some(match s.ssi_signo {
                2 => "SIGINT".to_string(),
                15 => "SIGTERM".to_string(),
                n => format!("signal {n}"),
            }),
            _ => None,
        }
    };
    let mut link = match (o.role, &o.port, &o.pty) {
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
    let mut writer: Option<Box<dyn Writer>> = match &o.write {
        Some(w) => Some(create(w, Format::for_writing(w, None)?, o.force)?),
        None => None,
    };
    let rec = writer.as_mut().map(|w| &mut **w as &mut dyn Writer);
    let display = !o.quiet;
    let mut show = |l: &str| {
        let _ = writeln!(out, "{l}");
    };
    match o.role {
        Role::Host => {
            let port = o.port.clone().unwrap_or_default();
            aptscope_capture::note!(
                "# replaying {} messages to {port} as the host ({line}{})",
                plan.len(),
                if o.wait_replies {
                    ", waiting for replies"
                } else {
                    ""
                }
            );
            let opts = HostOptions {
                timing: timing(&o, &script),
                loops: o.loops,
                wait_replies: o.wait_replies || !script.has_times(),
                reply_timeout_ns: o.reply_timeout_ns,
                stop_on_abort: o.stop_on_abort,
                ignore: o.ignore.clone(),
                display,
                json: o.json,
            };
            let r = run_host(&script, &sel, &opts, &mut link, rec, &mut show, &mut abort)?;
            drop(link);
            let fails = r.report.failures(o.latency_tolerance_ns);
            let mut out = io::stdout().lock();
            if o.json {
                let mut v = r.report.json(o.latency_tolerance_ns);
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
                write!(out, "{}", r.report.text(o.latency_tolerance_ns))?;
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
            Ok(!(o.check && fails > 0))
        }
        Role::Device => {
            aptscope_capture::note!("# answering as the captured device ({line}); Ctrl-C to stop");
            let opts = DeviceOptions {
                speed: if o.speed > 0.0 { o.speed } else { 1.0 },
                duration_ns: o.duration_ns,
                display,
                json: o.json,
            };
            let r = run_device(&script, &sel, &opts, &mut link, rec, &mut show, &mut abort)?;
            drop(link);
            let mut out = io::stdout().lock();
            if o.json {
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
            Ok(!o.check || r.unmatched.is_empty())
        }
    }
}
