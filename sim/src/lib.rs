//! Device simulators: a Thorlabs APT controller ([`AptSim`]) and an Elliptec multi-drop bus
//! ([`EllSim`]), each a sans-io core driven by bytes and a clock in nanoseconds. The serial I/O
//! that serves them on a pseudo-terminal or a port lives in `aptscope-capture`
//! (`live::sim::run_on_pty`).
//!
//! A core never reads a clock: the caller passes `now_ns` (any monotonic origin). It parses what
//! the host sends with the dissector's framers, answers through the table-driven encoder, and
//! paces its output like the real line (APT at 115 200 baud, Elliptec at 9600 baud), so replies,
//! move completions and status updates come out of [`Simulator::poll`] at the time they would
//! finish arriving at the host.

mod apt;
mod ell;
pub mod models;

pub use apt::{model_list, AptModel, AptSim};
pub use ell::{model_list as ell_model_list, parse_modules, EllModel, EllSim, SimError};

use std::collections::VecDeque;

/// A sans-io device simulator: bytes in, bytes out, driven by the caller's clock.
pub trait Simulator {
    /// Bytes the host sent, received at `now_ns`.
    fn input(&mut self, bytes: &[u8], now_ns: u64);
    /// Bytes to send to the host now (replies, completions, status updates whose time has
    /// come), or `None` when nothing is due. Call until it returns `None`.
    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>>;
    /// When [`poll`](Self::poll) will next have something to do (`None`: only after input).
    fn next_deadline(&self) -> Option<u64>;
    /// What the simulator noted since the last call (messages it ignored and why), for its
    /// runner to show; none by default.
    fn take_log(&mut self) -> Vec<String> {
        Vec::new()
    }
}

/// Nanoseconds per second.
pub const SEC: u64 = 1_000_000_000;
/// Nanoseconds per millisecond.
pub const MS: u64 = 1_000_000;

/// The device's transmit line: messages are queued with the time their last byte leaves, one
/// after the other, at the line's byte time after a turnaround delay.
#[derive(Debug, Clone)]
pub struct Line {
    byte_ns: u64,
    turnaround_ns: u64,
    free_at: u64,
    queue: VecDeque<(u64, Vec<u8>)>,
}

impl Line {
    /// A line sending a byte every `byte_ns`, answering `turnaround_ns` after the event.
    pub fn new(byte_ns: u64, turnaround_ns: u64) -> Line {
        Line {
            byte_ns,
            turnaround_ns,
            free_at: 0,
            queue: VecDeque::new(),
        }
    }

    /// Queue `bytes` for an event at `at_ns`.
    pub fn send(&mut self, at_ns: u64, bytes: Vec<u8>) {
        if bytes.is_empty() {
            return;
        }
        let start = at_ns.saturating_add(self.turnaround_ns).max(self.free_at);
        let due = start.saturating_add(self.byte_ns.saturating_mul(bytes.len() as u64));
        self.free_at = due;
        self.queue.push_back((due, bytes));
    }

    /// Everything whose last byte has left by `now_ns`, concatenated.
    pub fn take_due(&mut self, now_ns: u64) -> Option<Vec<u8>> {
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
    pub fn next_due(&self) -> Option<u64> {
        self.queue.front().map(|(d, _)| *d)
    }
}

/// The earlier of two optional deadlines.
pub fn earliest(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(x), Some(y)) => Some(x.min(y)),
        (x, None) => x,
        (None, y) => y,
    }
}

/// The APT controller `model` names (`kdc101` …), or an error listing the models.
pub fn apt_sim(model: &str) -> Result<AptSim, SimError> {
    let m = AptModel::parse(model).ok_or_else(|| SimError::UnknownApt(model.into()))?;
    Ok(AptSim::new(m))
}

/// The Elliptec bus `modules` describes (`0:ELL14,1:ELL9`), or why it cannot be.
pub fn ell_sim(modules: &str) -> Result<EllSim, SimError> {
    EllSim::new(&parse_modules(modules)?)
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod tests_models;

#[cfg(test)]
mod ell_tests;
