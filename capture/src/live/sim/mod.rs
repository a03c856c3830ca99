//! Serving the device simulators of `aptscope-sim` (re-exported here): runners that serve a
//! sans-io core on a pseudo-terminal ([`run_on_pty`]) or a real serial port ([`run_on_port`]),
//! and the `aptscope sim` entry points.

mod run;

pub use aptscope_sim::*;
pub use run::{
    run_on_port, run_on_pty, serve_pty, stop_pair, termination_signals, Pty, StopHandle, StopSignal,
};

use std::io;
use std::path::Path;

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

/// A simulator whose log lines (messages it ignored and why) go to standard error as they come,
/// `aptscope sim: …`.
struct Logged<S>(S);

impl<S: Simulator> Logged<S> {
    fn show(&mut self) {
        for l in self.0.take_log() {
            eprintln!("aptscope sim: {l}");
        }
    }
}

impl<S: Simulator> Simulator for Logged<S> {
    fn input(&mut self, bytes: &[u8], now_ns: u64) {
        self.0.input(bytes, now_ns);
        self.show();
    }

    fn poll(&mut self, now_ns: u64) -> Option<Vec<u8>> {
        let out = self.0.poll(now_ns);
        self.show();
        out
    }

    fn next_deadline(&self) -> Option<u64> {
        self.0.next_deadline()
    }
}

/// `aptscope sim apt --model MODEL [--pty LINK | --port DEV]`: simulate an APT controller
/// (any model of the spec: `sim apt --list`) on a new pseudo-terminal (its path printed, and
/// linked at `LINK`) or a serial port, until SIGINT/SIGTERM or until the program using the
/// pseudo-terminal hangs up. What the simulator ignores, and why, goes to standard error.
pub fn sim_apt_main(model: &str, line: SimLine<'_>) -> io::Result<()> {
    serve(Logged(aptscope_sim::apt_sim(model).map_err(invalid)?), line)
}

/// `aptscope sim elliptec --modules 0:ELL14,1:ELL9 [--pty LINK | --port DEV]`: simulate an
/// Elliptec bus with these modules, as [`sim_apt_main`] does.
pub fn sim_elliptec_main(modules: &str, line: SimLine<'_>) -> io::Result<()> {
    serve(aptscope_sim::ell_sim(modules).map_err(invalid)?, line)
}

#[cfg(test)]
mod pty_tests;
