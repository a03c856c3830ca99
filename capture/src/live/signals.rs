//! The one signal set-up of live tools: the stop signals blocked in the calling thread (and
//! the threads it starts, which inherit the mask) and received through a `signalfd`, so a
//! Ctrl-C ends a run cleanly instead of killing the process mid-write.

use nix::poll::PollFlags;
use nix::sys::signal::{SigSet, SigmaskHow, Signal};
use nix::sys::signalfd::{SfdFlags, SignalFd};
use std::io;
use std::os::fd::{AsFd, BorrowedFd};
use std::time::Duration;

/// What stops a tap, a sniff or a live view: SIGINT, SIGTERM and SIGHUP (the terminal closed).
pub const STOP: &[Signal] = &[Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP];
/// What ends a simulator or a replay: SIGINT and SIGTERM.
pub const TERMINATE: &[Signal] = &[Signal::SIGINT, Signal::SIGTERM];

/// Signals blocked in this thread; the previous mask comes back on drop.
#[derive(Debug)]
pub struct Blocked {
    set: SigSet,
    old: SigSet,
}

impl Blocked {
    /// Block `signals` in this thread (threads started from now on inherit it).
    pub fn new(signals: &[Signal]) -> io::Result<Blocked> {
        let mut set = SigSet::empty();
        for s in signals {
            set.add(*s);
        }
        let old = set.thread_swap_mask(SigmaskHow::SIG_BLOCK)?;
        Ok(Blocked { set, old })
    }
}

impl Drop for Blocked {
    fn drop(&mut self) {
        let _ = self.old.thread_set_mask();
    }
}

/// Signals blocked and readable from a descriptor; on drop what is pending is consumed (so
/// unblocking does not deliver it, and kill us) and the previous mask restored.
#[derive(Debug)]
pub struct Signals {
    // Declared first: dropped (closed) before the mask is restored.
    fd: SignalFd,
    _blocked: Blocked,
}

impl Signals {
    /// Block `signals` ([`STOP`], [`TERMINATE`]) and open their descriptor.
    pub fn install(signals: &[Signal]) -> io::Result<Signals> {
        let blocked = Blocked::new(signals)?;
        // On failure `blocked` is dropped: the mask is restored.
        let fd =
            SignalFd::with_flags(&blocked.set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC)?;
        Ok(Signals {
            fd,
            _blocked: blocked,
        })
    }

    /// A signal received within `timeout`, by name (`SIGINT`).
    pub fn wait(&self, timeout: Duration) -> Option<String> {
        if !super::wait_fd(self.fd.as_fd(), PollFlags::POLLIN, timeout).unwrap_or(false) {
            return None;
        }
        self.take()
    }

    /// A signal already received, by name (`SIGINT`), without waiting.
    pub fn take(&self) -> Option<String> {
        let si = self.fd.read_signal().ok()??;
        Some(
            Signal::try_from(si.ssi_signo as i32)
                .map(|s| s.as_str().to_string())
                .unwrap_or_else(|_| format!("signal {}", si.ssi_signo)),
        )
    }
}

impl AsFd for Signals {
    /// Readable when a signal is pending (to wait in `poll` beside other descriptors).
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.fd.as_fd()
    }
}

impl Drop for Signals {
    fn drop(&mut self) {
        while self.take().is_some() {}
    }
}
