//! Device simulators: a Thorlabs APT controller ([`AptSim`]: KDC101, TDC001, KPZ101, BSC203,
//! TLS001 laser source, TTC001 TEC controller, KPA101 position aligner) and
//! an Elliptec multi-drop bus ([`EllSim`]), each a sans-io core driven by bytes and a clock in
//! nanoseconds, plus runners that serve a core on a pseudo-terminal ([`run_on_pty`]) or a real
//! serial port ([`run_on_port`]).
//!
//! A core never reads a clock: the caller passes `now_ns` (any monotonic origin). It parses what
//! the host sends with the dissector's framers, answers through the table-driven encoder, and
//! paces its output like the real line (APT at 115 200 baud, Elliptec at 9600 baud), so replies,
//! move completions and status updates come out of [`Simulator::poll`] at the time they would
//! finish arriving at the host.

mod apt;
mod ell;
mod run;

pub use apt::{AptModel, AptSim};
pub use ell::{model_list as ell_model_list, parse_modules, EllModel, EllSim, SimError};
pub use run::{
    run_on_port, run_on_pty, serve_pty, stop_pair, termination_signals, Pty, StopHandle, StopSignal,
};

use std::collections::VecDeque;
use std::io;
use std::path::Path;

/// A sans-io device simulator: bytes in, bytes out, driven by the caller's clock.
pub trait Simulator {
    /// Bytes the host sent, received at `now_ns`.
    fn input(&mut self, bytes: &[u8], now_ns: u64);
    /// Bytes to send to the host now (replies, completions, status updates whose time has
    /// come), or `None` when nothing is due. Call until it returns `None`.
    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>>;
    /// When [`poll`](Self::poll) will next have something to do (`None`: only after input).
    fn next_deadline(&self) -> Option<u64>;
}

/// Nanoseconds per second.
pub(crate) const SEC: u64 = 1_000_000_000;
/// Nanoseconds per millisecond.
pub(crate) const MS: u64 = 1_000_000;

/// The device's transmit line: messages are queued with the time their last byte leaves, one
/// after the other, at the line's byte time after a turnaround delay.
#[derive(Debug, Clone)]
pub(crate) struct Line {
    byte_ns: u64,
    turnaround_ns: u64,
    free_at: u64,
    queue: VecDeque<(u64, Vec<u8>)>,
}

impl Line {
    /// A line sending a byte every `byte_ns`, answering `turnaround_ns` after the event.
    pub(crate) fn new(byte_ns: u64, turnaround_ns: u64) -> Line {
        Line {
            byte_ns,
            turnaround_ns,
            free_at: 0,
            queue: VecDeque::new(),
        }
    }

    /// Queue `bytes` for an event at `at_ns`.
    pub(crate) fn send(&mut self, at_ns: u64, bytes: Vec<u8>) {
        if bytes.is_empty() {
            return;
        }
        let start = at_ns.saturating_add(self.turnaround_ns).max(self.free_at);
        let due = start.saturating_add(self.byte_ns.saturating_mul(bytes.len() as u64));
        self.free_at = due;
        self.queue.push_back((due, bytes));
    }

    /// Everything whose last byte has left by `now_ns`, concatenated.
    pub(crate) fn take_due(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        let mut out: Option<Vec<u8>> = None;
        while let Some((due, _)) = self.queue.front() {
            if *due > now_ns {
                break;
            }
            if let Some((_, b)) = self.queue.pop_front() {
                out.get_or_insert_with(Vec::new).extend_from_slice(&b);
            }
        }
        out
    }

    /// When the next queued message is due.
    pub(crate) fn next_due(&self) -> Option<u64> {
        self.queue.front().map(|(d, _)| *d)
    }
}

/// The earlier of two optional deadlines.
pub(crate) fn earliest(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

fn invalid(e: impl std::error::Error + Send + Sync + 'static) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, e)
}

/// Where a simulator serves.
#[derive(Debug, Clone, Copy)]
pub enum SimLine<'a> {
    /// A new pseudo-terminal, symlinked here when given, serving one host program after
    /// another until stopped.
    Pty(Option<&'a Path>),
    /// As [`SimLine::Pty`], but ending when the first host program hangs up.
    PtyOnce(Option<&'a Path>),
    /// A real serial port at this baud rate.
    Port(&'a Path, u32),
}

fn serve<S: Simulator>(sim: S, line: SimLine<'_>) -> io::Result<()> {
    match line {
        SimLine::Pty(link) => run_on_pty(sim, link, false),
        SimLine::PtyOnce(link) => run_on_pty(sim, link, true),
        SimLine::Port(dev, baud) => run_on_port(sim, dev, baud),
    }
}

/// `aptscope sim apt --model MODEL [--pty LINK | --port DEV]`: simulate an APT controller
/// (`kdc101`, `tdc001`, `kpz101`, `bsc203`, `tls001`, `ttc001`, `kpa101`) on a new
/// pseudo-terminal (its path printed, and linked at `LINK`) or a serial port, until
/// SIGINT/SIGTERM or until the program using the pseudo-terminal hangs up.
pub fn sim_apt_main(model: &str, line: SimLine<'_>) -> io::Result<()> {
    serve(apt_sim(model)?, line)
}

/// The APT controller `model` names (`kdc101` …), or an error listing the models.
pub fn apt_sim(model: &str) -> io::Result<AptSim> {
    let m = AptModel::parse(model).ok_or_else(|| invalid(SimError::UnknownApt(model.into())))?;
    Ok(AptSim::new(m))
}

/// The Elliptec bus `modules` describes (`0:ELL14,1:ELL9`), or why it cannot be.
pub fn ell_sim(modules: &str) -> io::Result<EllSim> {
    let mods = parse_modules(modules).map_err(invalid)?;
    EllSim::new(&mods).map_err(invalid)
}

/// `aptscope sim elliptec --modules 0:ELL14,1:ELL9 [--pty LINK | --port DEV]`: simulate an
/// Elliptec bus with these modules, as [`sim_apt_main`] does.
pub fn sim_elliptec_main(modules: &str, line: SimLine<'_>) -> io::Result<()> {
    serve(ell_sim(modules)?, line)
}

#[cfg(test)]
mod ell_tests;
#[cfg(test)]
mod tests;
