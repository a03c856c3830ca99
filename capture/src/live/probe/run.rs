//! The probe's I/O: open the port, identify the controller, send the plan one request at a time
//! and wait for each answer (or its timeout), recording the whole exchange.

use super::{answers, check_reply, frame_id, plan, Outcome, Report, Step, Stray, Unit};
use super::{ell, BAY0, HOST, RACK, USB};
use crate::live::error::PortError;
use crate::live::serial::{open_serial, LineSettings, SerialFd};
use crate::live::signals::{Signals, TERMINATE};
use crate::model::{Direction, OwnedChunk};
use aptscope_dissector::apt::{encode_named, AptFrame, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::table::{Class, DeviceProfile, MsgDef};
use aptscope_dissector::Table;
use nix::errno::Errno;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::io::{self, Write};
use std::os::fd::AsFd;
use std::time::{Duration, Instant};

/// How long identification waits for HW_GET_INFO before it says the port is not answering APT.
const IDENTIFY_MS: u32 = 2000;
/// The longest data packet the probe takes from a device (the table's longest is 1208 bytes);
/// a header claiming more is taken as a stray byte.
const MAX_DATA: usize = 4096;

/// What the probe is asked to do.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Also send the read-only requests the spec does not list for the model.
    pub unlisted: bool,
    /// Wait at most this long for any answer (the table's timeouts are the spec's bounds; a
    /// quick survey may want less).
    pub max_timeout_ms: Option<u32>,
    /// A second safety rule (the command line passes replay's): a request it refuses is
    /// dropped from the plan, whatever [`super::read_only`] said.
    pub refuse: Option<fn(&MsgDef) -> bool>,
}

/// Why a probe could not run.
#[derive(Debug, thiserror::Error)]
pub enum ProbeError {
    /// The port could not be opened.
    #[error(transparent)]
    Port(#[from] PortError),
    /// Reading or writing the port failed.
    #[error("{path}: {source}")]
    Io {
        /// The port's path.
        path: String,
        /// What the system said.
        source: io::Error,
    },
    /// No module answered `in` at any address.
    #[error("{path} does not answer Elliptec: no module answered `in` at addresses 0-F (is the bus powered, and the right port and protocol chosen?)")]
    NotElliptec {
        /// The port's path.
        path: String,
    },
    /// Nothing answered HW_REQ_INFO: the probe sends nothing else.
    #[error("{path} does not answer APT: no HW_GET_INFO within {ms} ms of HW_REQ_INFO (is the controller on, and the right port and protocol chosen?)")]
    NotApt {
        /// The port's path.
        path: String,
        /// How long it waited.
        ms: u32,
    },
    /// Ctrl-C (or SIGTERM) came during identification.
    #[error("{path}: interrupted by {signal} before the controller was identified")]
    Interrupted {
        /// The port's path.
        path: String,
        /// The signal.
        signal: String,
    },
}

/// The port, its receive buffer and everything said on it.
struct Line<'a> {
    path: &'a str,
    port: SerialFd,
    sigs: &'a Signals,
    start: Instant,
    rx: Vec<u8>,
    exchange: Vec<OwnedChunk>,
    /// The start as ns since the Unix epoch (the capture's clock).
    epoch_ns: u64,
    /// Elliptec: replies are lines.
    ell: bool,
}

/// What a request got.
enum Asked {
    /// Its answer, and the latency in µs.
    Reply(Vec<u8>, u64),
    /// None within its timeout.
    NoReply,
    /// A stop signal came first, by name.
    Signal(String),
}

impl Asked {
    /// The answer, or the error a stop signal during identification on `path` is.
    fn ident(self, path: &str) -> Result<Option<Vec<u8>>, ProbeError> {
        match self {
            Asked::Reply(f, _) => Ok(Some(f)),
            Asked::NoReply => Ok(None),
            Asked::Signal(signal) => Err(ProbeError::Interrupted {
                path: path.to_string(),
                signal,
            }),
        }
    }
}

/// What waiting for a frame ended with.
enum Got {
    /// A whole frame and when it was complete (ns since start).
    Frame(Vec<u8>, u64),
    /// The deadline passed.
    Timeout,
    /// A stop signal, by name.
    Signal(String),
}

/// SIGINT and SIGTERM, received through a descriptor the waits poll.
fn signals(path: &str) -> Result<Signals, ProbeError> {
    Signals::install(TERMINATE).map_err(|source| ProbeError::Io {
        path: path.to_string(),
        source,
    })
}

impl<'a> Line<'a> {
    /// Open `path` with `proto`'s line settings.
    fn open(path: &'a str, sigs: &'a Signals, proto: Proto) -> Result<Line<'a>, ProbeError> {
        let port = open_serial(path, &LineSettings::for_proto(proto, None, None))?;
        Ok(Line {
            path,
            port,
            sigs,
            start: Instant::now(),
            rx: vec![],
            exchange: vec![],
            epoch_ns: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)),
            ell: proto == Proto::Elliptec,
        })
    }

    fn err(&self, source: io::Error) -> ProbeError {
        ProbeError::Io {
            path: self.path.to_string(),
            source,
        }
    }

    fn record(&mut self, dir: Direction, bytes: &[u8], ts: u64) {
        self.exchange.push(OwnedChunk {
            ts_ns: Some(self.epoch_ns.saturating_add(ts)),
            dir,
            stream: 0,
            bytes: bytes.to_vec(),
        });
    }

    fn now_ns(&self) -> u64 {
        u64::try_from(self.start.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    /// Send `bytes` whole; the time just before the write that handed over its last bytes
    /// (taken after it, a probe descheduled on a loaded machine would measure a reply that was
    /// already waiting as answered in microseconds).
    fn send(&mut self, bytes: &[u8]) -> Result<u64, ProbeError> {
        let mut rest = bytes;
        let mut ts = self.now_ns();
        while !rest.is_empty() {
            ts = self.now_ns();
            match self.port.file.write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    let mut fds = [PollFd::new(self.port.file.as_fd(), PollFlags::POLLOUT)];
                    match poll(&mut fds, PollTimeout::from(100u16)) {
                        Ok(_) | Err(Errno::EINTR) => {}
                        Err(e) => return Err(self.err(e.into())),
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(self.err(e)),
            }
        }
        self.record(Direction::HostToDevice, bytes, ts);
        Ok(ts)
    }

    /// A whole frame from the receive buffer, by the header's own length (not the table's: a
    /// frame of a length the table does not know is what the probe is there to report).
    fn take_frame(&mut self) -> Option<Vec<u8>> {
        if self.ell {
            return self.take_line();
        }
        loop {
            if self.rx.len() < 6 {
                return None;
            }
            let len = if self.rx[4] & 0x80 != 0 {
                usize::from(u16::from_le_bytes([self.rx[2], self.rx[3]]))
            } else {
                0
            };
            if len > MAX_DATA {
                self.rx.remove(0);
                continue;
            }
            if self.rx.len() < 6 + len {
                return None;
            }
            return Some(self.rx.drain(..6 + len).collect());
        }
    }

    /// An Elliptec reply line, without its CR LF (empty lines skipped).
    fn take_line(&mut self) -> Option<Vec<u8>> {
        loop {
            let end = self.rx.iter().position(|b| *b == b'\n')?;
            let mut l: Vec<u8> = self.rx.drain(..=end).collect();
            while l.last().is_some_and(|b| *b == b'\n' || *b == b'\r') {
                l.pop();
            }
            if !l.is_empty() {
                return Some(l);
            }
        }
    }

    /// The next frame, waiting until `deadline` at most.
    fn recv(&mut self, deadline: Instant) -> Result<Got, ProbeError> {
        let mut buf = [0u8; 4096];
        loop {
            if let Some(f) = self.take_frame() {
                return Ok(Got::Frame(f, self.now_ns()));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(Got::Timeout);
            }
            let ms = u16::try_from(left.as_millis().max(1)).unwrap_or(u16::MAX);
            let mut fds = [
                PollFd::new(self.port.file.as_fd(), PollFlags::POLLIN),
                PollFd::new(self.sigs.as_fd(), PollFlags::POLLIN),
            ];
            match poll(&mut fds, PollTimeout::from(ms)) {
                Ok(_) | Err(Errno::EINTR) => {}
                Err(e) => return Err(self.err(e.into())),
            }
            let sig = fds[1].revents().is_some_and(|r| !r.is_empty());
            if sig {
                if let Some(s) = self.sigs.take() {
                    return Ok(Got::Signal(s));
                }
            }
            match io::Read::read(&mut self.port.file, &mut buf) {
                Ok(0) => {}
                Ok(n) => {
                    let ts = self.now_ns();
                    self.record(Direction::DeviceToHost, &buf[..n], ts);
                    self.rx.extend_from_slice(&buf[..n]);
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(self.err(e)),
            }
        }
    }

    /// Send `step` and wait for its answer; what else came meanwhile goes to `strays`.
    fn ask(
        &mut self,
        step: &Step,
        timeout_ms: u32,
        strays: &mut Vec<Stray>,
    ) -> Result<Asked, ProbeError> {
        let sent = self.send(&step.bytes)?;
        let deadline = Instant::now() + Duration::from_millis(u64::from(timeout_ms));
        loop {
            match self.recv(deadline)? {
                Got::Frame(f, ts) if self.ell && ell::answers(step, &f) => {
                    return Ok(Asked::Reply(f, ts.saturating_sub(sent) / 1000))
                }
                Got::Frame(f, _) if self.ell => strays.push(Stray {
                    name: String::from_utf8_lossy(f.get(1..3).unwrap_or(&[])).into_owned(),
                    src: f.first().copied().unwrap_or(0),
                    len: f.len().saturating_sub(3),
                    during: step.label(),
                }),
                Got::Frame(f, ts) if answers(step, &f) => {
                    return Ok(Asked::Reply(f, ts.saturating_sub(sent) / 1000))
                }
                Got::Frame(f, _) => {
                    let ours = Table::global()
                        .msg_by_name(step.name)
                        .is_some_and(|m| Table::global().reply_ids(m).contains(&frame_id(&f)));
                    stray(&f, &step.label(), ours, strays)
                }
                Got::Timeout => return Ok(Asked::NoReply),
                Got::Signal(s) => return Ok(Asked::Signal(s)),
            }
        }
    }
}

/// Note `f`, which answered nothing, unless it is a status update (those come on their own).
/// (`ours`: it is of the message the request waits for, from another address or channel: noted
/// even when a status update).
fn stray(f: &[u8], during: &str, ours: bool, strays: &mut Vec<Stray>) {
    let t = Table::global();
    let id = frame_id(f);
    let m = t.msg(id);
    if !ours && m.is_some_and(|m| m.class.has(Class::STATUS)) {
        return;
    }
    strays.push(Stray {
        name: m.map_or_else(|| format!("0x{id:04X}"), |m| m.name.to_string()),
        src: f.get(5).copied().unwrap_or(0),
        len: f.len().saturating_sub(6),
        during: during.to_string(),
    });
}

/// An identification request (HW_REQ_INFO, RACK_REQ_BAYUSED) as a step of no plan.
fn ident_step(name: &'static str, dst: u8, values: &[(&str, &str)]) -> Step {
    let t = Table::global();
    let bytes = encode_named(
        t,
        &Named {
            name,
            sub: None,
            values,
            form: None,
            dst,
            src: HOST,
        },
    )
    .unwrap_or_default();
    Step {
        name,
        sub: None,
        dst,
        chan: None,
        bytes,
        timeout_ms: IDENTIFY_MS,
        listed: true,
    }
}

/// The unit an HW_GET_INFO `frame` from `addr` describes.
fn unit_of(addr: u8, frame: &[u8]) -> Option<(Unit, i64)> {
    let f = AptFrame::decode(Table::global(), 0, frame, false)?;
    let int = |n: &str| f.field(n).and_then(|(_, v)| v.as_i64());
    let model = f.field("model_number").map(|(_, v)| match v {
        aptscope_dissector::apt::Value::Str(b) | aptscope_dissector::apt::Value::Bytes(b) => {
            aptscope_dissector::apt::text_of(b)
                .trim_matches(|c: char| c == '\0' || c.is_whitespace())
                .to_string()
        }
        _ => String::new(),
    })?;
    let fw = format!(
        "{}.{}.{}",
        int("fw_major")?,
        int("fw_interim")?,
        int("fw_minor")?
    );
    let nchs = int("nchs").unwrap_or(1);
    Some((
        Unit {
            addr,
            model,
            serial: int("serial_number")?,
            firmware: fw,
            channels: u16::try_from(nchs.clamp(1, 16)).unwrap_or(1),
        },
        int("hw_type").unwrap_or(0),
    ))
}

/// Identify the controller on `path`: HW_REQ_INFO at 0x50; a rack (hardware type 45, the
/// multi-channel motherboard) is then asked RACK_REQ_BAYUSED for each bay it reports and each
/// occupied bay HW_REQ_INFO. Returns the rack's or the unit's model, and the units to probe.
fn identify(
    line: &mut Line<'_>,
    strays: &mut Vec<Stray>,
) -> Result<(String, Vec<Unit>), ProbeError> {
    let not_apt = || ProbeError::NotApt {
        path: line.path.to_string(),
        ms: IDENTIFY_MS,
    };
    let path = line.path;
    let info = ident_step("HW_REQ_INFO", USB, &[]);
    let f = line
        .ask(&info, IDENTIFY_MS, strays)?
        .ident(path)?
        .ok_or_else(not_apt)?;
    let (top, hw_type) = unit_of(USB, &f).ok_or_else(not_apt)?;
    if hw_type != 45 {
        return Ok((top.model.clone(), vec![top]));
    }
    let mut units = vec![];
    for bay in 0..top.channels.min(10) {
        let b = bay.to_string();
        let q = ident_step("RACK_REQ_BAYUSED", RACK, &[("bay_ident", &b)]);
        let Some(f) = line.ask(&q, IDENTIFY_MS, strays)?.ident(path)? else {
            continue;
        };
        // RACK_GET_BAYUSED: header byte 3 is the bay's state, 1 = occupied.
        if f.get(3) != Some(&1) {
            continue;
        }
        let addr = BAY0 + bay as u8;
        let q = ident_step("HW_REQ_INFO", addr, &[]);
        if let Some(f) = line.ask(&q, IDENTIFY_MS, strays)?.ident(path)? {
            if let Some((u, _)) = unit_of(addr, &f) {
                units.push(u);
            }
        }
    }
    Ok((top.model, units))
}

/// Send `steps` one at a time (their timeouts capped by `opts`), each answer judged by
/// `judge`, into `report`; a stop signal ends it, the report marked interrupted.
fn run_plan(
    line: &mut Line<'_>,
    steps: &[Step],
    opts: &Options,
    strays: &mut Vec<Stray>,
    report: &mut Report,
    judge: impl Fn(&Step, &[u8], u64) -> super::Reply,
) -> Result<(), ProbeError> {
    for step in steps {
        let mut step = step.clone();
        if let Some(m) = opts.max_timeout_ms {
            step.timeout_ms = step.timeout_ms.min(m);
        }
        let reply = match line.ask(&step, step.timeout_ms, strays)? {
            Asked::Signal(_) => {
                report.interrupted = true;
                break;
            }
            Asked::Reply(f, lat) => Some(judge(&step, &f, lat)),
            Asked::NoReply => None,
        };
        report.outcomes.push(Outcome { step, reply });
    }
    Ok(())
}

/// The device profile of `model` (`None` when the table has no list for it).
pub fn profile_of(model: &str) -> Option<DeviceProfile> {
    Table::global().device_profile(model)
}

/// Probe the controller (APT) or bus (Elliptec) on `path`: a serial port, or a pseudo-terminal
/// such as a simulator's `--pty` link. SIGINT or SIGTERM ends it at once (after the request in
/// flight, which is read-only), the report saying so. `dry_run`: identify, then return the plan
/// without sending it.
pub fn probe(
    path: &str,
    proto: Proto,
    opts: &Options,
    dry_run: bool,
) -> Result<(Report, Vec<Step>), ProbeError> {
    let sigs = signals(path)?;
    let mut line = Line::open(path, &sigs, proto)?;
    match proto {
        Proto::Apt => probe_apt(&mut line, opts, dry_run),
        Proto::Elliptec => probe_elliptec(&mut line, opts, dry_run),
    }
}

/// The APT probe: identify the controller, then send every read-only request of its plan one
/// at a time.
fn probe_apt(
    line: &mut Line<'_>,
    opts: &Options,
    dry_run: bool,
) -> Result<(Report, Vec<Step>), ProbeError> {
    let path = line.path;
    let mut strays = vec![];
    let (model, units) = identify(line, &mut strays)?;
    let profile = profile_of(&model);
    let mut steps = plan(profile.as_ref(), &units, opts.unlisted);
    if let Some(refuse) = opts.refuse {
        let t = Table::global();
        steps.retain(|s| t.msg_by_name(s.name).is_some_and(|m| !refuse(m)));
    }
    let mut report = Report {
        port: path.to_string(),
        model,
        profiled: profile.is_some(),
        units,
        ..Report::default()
    };
    if dry_run {
        report.exchange = std::mem::take(&mut line.exchange);
        return Ok((report, steps));
    }
    run_plan(line, &steps, opts, &mut strays, &mut report, |_, f, lat| {
        check_reply(f, lat, profile.as_ref())
    })?;
    // What is still in the buffer answered nothing either.
    while let Some(f) = line.take_frame() {
        stray(&f, "the end", false, &mut strays);
    }
    report.strays = strays;
    report.exchange = std::mem::take(&mut line.exchange);
    Ok((report, steps))
}

/// The Elliptec probe: `in` at every address 0–F (each waiting [`ell::SCAN_MS`]), then every
/// query each module's model supports, one at a time.
fn probe_elliptec(
    line: &mut Line<'_>,
    opts: &Options,
    dry_run: bool,
) -> Result<(Report, Vec<Step>), ProbeError> {
    let path = line.path;
    let mut strays = vec![];
    let mut report = Report {
        port: path.to_string(),
        model: "Elliptec bus".into(),
        profiled: true,
        elliptec: true,
        ..Report::default()
    };
    let mut steps = vec![];
    for addr in 0..16u8 {
        let mut s = ell::scan_step(addr);
        if let Some(m) = opts.max_timeout_ms {
            s.timeout_ms = s.timeout_ms.min(m);
        }
        let got = line.ask(&s, s.timeout_ms, &mut strays)?;
        let f = match got {
            Asked::Reply(f, lat) => {
                let reply = ell::check(&s, &f, lat);
                report.outcomes.push(Outcome {
                    step: s,
                    reply: Some(reply),
                });
                f
            }
            Asked::NoReply => {
                report.outcomes.push(ell::empty_address(s));
                continue;
            }
            Asked::Signal(signal) => {
                return Err(ProbeError::Interrupted {
                    path: path.to_string(),
                    signal,
                })
            }
        };
        let Some(n) = ell::model_of(&f) else {
            continue;
        };
        let text = |r: std::ops::Range<usize>| {
            String::from_utf8_lossy(f.get(r).unwrap_or(&[])).into_owned()
        };
        report.units.push(Unit {
            addr,
            model: format!("ELL{n}"),
            serial: text(5..13).trim().parse().unwrap_or(0),
            firmware: text(17..19),
            channels: 1,
        });
        steps.extend(ell::plan(addr, n));
    }
    if report.units.is_empty() {
        return Err(ProbeError::NotElliptec {
            path: path.to_string(),
        });
    }
    if !dry_run {
        run_plan(line, &steps, opts, &mut strays, &mut report, ell::check)?;
    }
    report.strays = strays;
    report.exchange = std::mem::take(&mut line.exchange);
    Ok((report, steps))
}

#[cfg(test)]
mod tests {
    use super::super::read_only;
    use aptscope_dissector::Table;

    #[test]
    fn no_plan_holds_a_message_that_moves_or_sets() {
        let t = Table::global();
        for m in t.msgs().iter().filter(|m| read_only(m)) {
            assert!(!m.name.contains("_SET_"), "{}", m.name);
            assert!(!m.name.contains("_MOVE_"), "{}", m.name);
        }
        let named = |n: &str| t.msg_by_name(n).is_some_and(read_only);
        assert!(named("HW_REQ_INFO"));
        assert!(named("MOT_REQ_VELPARAMS"));
        assert!(!named("MOT_MOVE_HOME"));
        assert!(!named("MOD_IDENTIFY"));
        assert!(!named("MOT_SET_VELPARAMS"));
    }
}
