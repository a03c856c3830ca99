//! One stop handle for everything live: taps, sniffs, live views and the simulators' runner.

use std::io;
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, OnceLock};
use std::time::Duration;

#[derive(Debug, Default)]
struct Inner {
    flag: AtomicBool,
    m: Mutex<()>,
    cv: Condvar,
    /// A pipe made readable by the stop, for loops that wait in `poll` (made on first ask).
    pipe: OnceLock<(OwnedFd, OwnedFd)>,
}

/// Stops a running tap, sniff or simulator from another thread (as Ctrl-C does). Clones stop
/// the same run. Threads wait on it with [`StopHandle::wait`]; poll loops watch
/// [`StopHandle::pollable`].
#[derive(Debug, Clone, Default)]
pub struct StopHandle(Arc<Inner>);

impl StopHandle {
    /// A fresh handle, not stopped.
    pub fn new() -> Self {
        Self::default()
    }

    /// Ask the run to stop (idempotent): a tap finishes its file and returns its statistics,
    /// a simulator's runner returns.
    pub fn stop(&self) {
        let first = !self.0.flag.swap(true, Ordering::SeqCst);
        {
            let _g = lock(&self.0.m);
            self.0.cv.notify_all();
        }
        if first {
            if let Some((_, w)) = self.0.pipe.get() {
                poke(w);
            }
        }
    }

    /// Whether a stop was asked for.
    pub fn is_stopped(&self) -> bool {
        self.0.flag.load(Ordering::SeqCst)
    }

    /// Wait up to `d` for a stop (or a [`StopHandle::wake`]); returns whether stopped.
    pub fn wait(&self, d: Duration) -> bool {
        let g = lock(&self.0.m);
        if self.is_stopped() {
            return true;
        }
        drop(self.0.cv.wait_timeout(g, d));
        self.is_stopped()
    }

    /// Wake waiters without stopping (something else changed).
    pub fn wake(&self) {
        let _g = lock(&self.0.m);
        self.0.cv.notify_all();
    }

    /// A descriptor that becomes readable once the handle is stopped (and stays so), for
    /// waiting in `poll` beside other descriptors.
    pub fn pollable(&self) -> io::Result<BorrowedFd<'_>> {
        let (r, _) = match self.0.pipe.get() {
            Some(p) => p,
            None => {
                let (r, w) = nix::unistd::pipe()?;
                set_nonblocking(&w)?;
                let mut made = false;
                let p = self.0.pipe.get_or_init(|| {
                    made = true;
                    (r, w)
                });
                // A stop before the pipe existed wrote nothing into it: say it now. (Both
                // sides may poke; one byte or two makes no difference.)
                if made && self.is_stopped() {
                    poke(&p.1);
                }
                p
            }
        };
        Ok(r.as_fd())
    }
}

/// Make the pipe readable; a full pipe is readable already.
fn poke(w: &OwnedFd) {
    let _ = nix::unistd::write(w, b"x");
}

fn set_nonblocking(fd: &OwnedFd) -> io::Result<()> {
    use nix::fcntl::{fcntl, FcntlArg, OFlag};
    let fl = fcntl(fd, FcntlArg::F_GETFL)?;
    fcntl(
        fd,
        FcntlArg::F_SETFL(OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK),
    )?;
    Ok(())
}

/// Lock, ignoring poisoning (a panicked holder leaves plain data behind).
pub(crate) fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nix::poll::{poll, PollFd, PollFlags, PollTimeout};

    fn readable(fd: BorrowedFd<'_>) -> bool {
        let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
        poll(&mut fds, PollTimeout::ZERO).unwrap() > 0
    }

    #[test]
    fn the_pipe_says_a_stop_made_before_or_after_it() {
        let before = StopHandle::new();
        before.stop();
        assert!(readable(before.pollable().unwrap()));
        let after = StopHandle::new();
        let waiter = after.clone();
        assert!(!readable(waiter.pollable().unwrap()));
        assert!(!after.wait(Duration::ZERO));
        after.stop();
        after.stop();
        assert!(readable(waiter.pollable().unwrap()));
        assert!(waiter.wait(Duration::ZERO));
    }
}
