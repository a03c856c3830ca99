//! Serving a simulator on a pseudo-terminal or a serial port.

use super::Simulator;
use crate::live::error::LiveError;
use crate::live::pty::Link;
use crate::live::serial::open_serial;
use crate::live::serial::{Flow, LineSettings};
use crate::live::signals::{Signals, TERMINATE};
use nix::errno::Errno;
use nix::fcntl::OFlag;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::io::{self, Write};
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::Path;
use std::time::Instant;

/// Output not yet taken by the peer is dropped beyond this (like a full FTDI buffer).
const MAX_PENDING: usize = 64 * 1024;

pub use crate::live::pty::Pty;
pub use crate::live::stop::StopHandle;

/// What [`serve_pty`] watches: the same [`StopHandle`] as the one that stops it (a clone).
pub type StopSignal = StopHandle;

/// A stop handle and a clone of it to give to [`serve_pty`] (its descriptor already made, so
/// the runner cannot fail for want of one).
pub fn stop_pair() -> io::Result<(StopHandle, StopSignal)> {
    let stop = StopHandle::new();
    stop.pollable()?;
    Ok((stop.clone(), stop))
}

/// Poll timeout until `deadline_ns` on the clock of `start` (rounded up to whole ms).
fn timeout_until(deadline_ns: Option<u64>, now_ns: u64) -> PollTimeout {
    match deadline_ns {
        None => PollTimeout::NONE,
        Some(d) => {
            let ms = d.saturating_sub(now_ns).div_ceil(1_000_000);
            PollTimeout::try_from(ms).unwrap_or(PollTimeout::MAX)
        }
    }
}

fn elapsed_ns(start: Instant) -> u64 {
    u64::try_from(start.elapsed().as_nanos()).unwrap_or(u64::MAX)
}

/// Serve `sim` on `pty` until `stop` (or any of `extra_stops`) becomes readable, or the peer
/// hangs up. The simulator's clock is the time since the call. Our own copy of the slave is
/// kept open until the peer first sends something (so the line stays up before a program has
/// opened it), then closed, so the peer closing its end is seen as a hang-up.
pub fn serve_pty<S: Simulator + ?Sized>(
    sim: &mut S,
    pty: Pty,
    stop: Option<&StopSignal>,
    extra_stops: &[BorrowedFd<'_>],
) -> io::Result<()> {
    let mut stops: Vec<BorrowedFd<'_>> = vec![];
    if let Some(s) = stop {
        stops.push(s.pollable()?);
    }
    stops.extend_from_slice(extra_stops);
    let (master, slave, _) = pty.into_parts();
    serve_fd(sim, &master, slave, &stops, Line::Pty, Instant::now())
        .map(|_| ())
        .map_err(io::Error::from)
}

/// Why serving ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    /// A stop descriptor became readable (signal, stop handle).
    Stopped,
    /// The program on the other end closed the line.
    HungUp,
}

/// What the simulator serves on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Line<'a> {
    /// A pseudo-terminal's master: the peer closing its end is the normal end.
    Pty,
    /// A real serial port (this one): it vanishing is an error.
    Port(&'a Path),
}

/// Serve `sim` on the non-blocking descriptor `fd` until one of `stops` becomes readable or
/// the line goes away; `slave`: our copy of a pseudo-terminal's slave, dropped once the peer
/// has spoken (see [`serve_pty`]).
fn serve_fd<S: Simulator + ?Sized>(
    sim: &mut S,
    fd: &OwnedFd,
    mut slave: Option<OwnedFd>,
    stops: &[BorrowedFd<'_>],
    line: Line,
    start: Instant,
) -> Result<End, LiveError> {
    let gone = || match line {
        Line::Pty => Ok(End::HungUp),
        Line::Port(path) => Err(LiveError::PortGone {
            path: path.display().to_string(),
        }),
    };
    let mut pending: Vec<u8> = vec![];
    let mut buf = [0u8; 4096];
    loop {
        let now = elapsed_ns(start);
        while let Some(out) = sim.poll(now) {
            pending.extend_from_slice(&out);
        }
        if pending.len() > MAX_PENDING {
            let cut = pending.len() - MAX_PENDING;
            pending.drain(..cut);
        }
        // Write what the pty takes now.
        while !pending.is_empty() {
            match nix::unistd::write(fd, &pending) {
                Ok(n) => {
                    pending.drain(..n);
                }
                Err(Errno::EAGAIN) | Err(Errno::EINTR) => break,
                Err(Errno::EIO) => return gone(), // peer gone
                Err(e) => return Err(e.into()),
            }
        }
        let timeout = timeout_until(sim.next_deadline(), elapsed_ns(start));
        let mut ev = PollFlags::POLLIN;
        if !pending.is_empty() {
            ev |= PollFlags::POLLOUT;
        }
        let mut fds = vec![PollFd::new(fd.as_fd(), ev)];
        for s in stops {
            fds.push(PollFd::new(*s, PollFlags::POLLIN));
        }
        match poll(&mut fds, timeout) {
            Ok(_) | Err(Errno::EINTR) => {}
            Err(e) => return Err(e.into()),
        }
        let revents: Vec<PollFlags> = fds
            .iter()
            .map(|f| f.revents().unwrap_or(PollFlags::empty()))
            .collect();
        drop(fds);
        if revents[1..].iter().any(|r| !r.is_empty()) {
            return Ok(End::Stopped);
        }
        let m = revents[0];
        if m.contains(PollFlags::POLLIN) {
            match nix::unistd::read(fd, &mut buf) {
                Ok(0) | Err(Errno::EIO) => {
                    if slave.is_none() {
                        return gone();
                    }
                }
                Ok(n) => {
                    sim.input(&buf[..n], elapsed_ns(start));
                    // The peer is connected: from now on its hang-up ends the run.
                    slave = None;
                }
                Err(Errno::EAGAIN) | Err(Errno::EINTR) => {}
                Err(e) => return Err(e.into()),
            }
        } else if m.intersects(PollFlags::POLLHUP | PollFlags::POLLERR) && slave.is_none() {
            return gone();
        }
    }
}

/// SIGINT and SIGTERM, blocked in this thread (threads started later inherit it) and readable
/// from a descriptor, so the runner can end cleanly on them (see [`crate::live::signals`]).
pub fn termination_signals() -> io::Result<Signals> {
    Signals::install(TERMINATE)
}

/// Serve `sim` on a new pseudo-terminal: print its path on stdout (and make `link` a symlink to
/// it, replacing an older symlink, removed again on exit), then run until SIGINT/SIGTERM. A real
/// controller does not vanish when the host closes the port: the simulator serves one host
/// program after another (with `once`, it ends when the first one hangs up). Call it from the
/// main thread before starting others: it blocks SIGINT/SIGTERM in the calling thread to
/// receive them through a descriptor.
pub fn run_on_pty<S: Simulator>(sim: S, link: Option<&Path>, once: bool) -> io::Result<()> {
    Ok(serve_on_pty(sim, link, once)?)
}

/// [`run_on_pty`], its error saying what it concerns.
fn serve_on_pty<S: Simulator>(
    mut sim: S,
    link: Option<&Path>,
    once: bool,
) -> Result<(), LiveError> {
    let sigs = termination_signals()?;
    let pty = Pty::open()?;
    let path = pty.path().to_path_buf();
    // Removed on return while it is still ours (a simulator started since at the same path
    // has replaced it otherwise).
    let _link = match link {
        Some(l) => Some(Link::create(l, &path)?),
        None => None,
    };
    {
        let mut out = io::stdout().lock();
        match link {
            Some(l) => writeln!(out, "{} -> {}", l.display(), path.display())?,
            None => writeln!(out, "{}", path.display())?,
        }
        out.flush()?;
    }
    let start = Instant::now();
    let (master, mut slave, _) = pty.into_parts();
    let r = loop {
        match serve_fd(
            &mut sim,
            &master,
            slave.take(),
            &[sigs.as_fd()],
            Line::Pty,
            start,
        ) {
            Ok(End::HungUp) if !once => {
                // Hold the line up again for the next program, without what the last one left
                // unread (the simulator's clock and state go on, as a controller's would).
                match reopen_slave(&path) {
                    Ok(fd) => slave = Some(fd),
                    Err(e) => break Err(e),
                }
            }
            r => break r.map(|_| ()),
        }
    };
    r
}

/// Open our own copy of a pseudo-terminal's slave again (so the master sees no hang-up while no
/// program has it open), dropping what the last program left unread. Only that direction: the
/// next program may already have opened the line and sent its first request before the hang-up
/// was seen (flushing both ways lost it: a CI run of the sessions test waited a minute for a
/// reply).
fn reopen_slave(path: &Path) -> Result<OwnedFd, LiveError> {
    let fd = nix::fcntl::open(
        path,
        OFlag::O_RDWR | OFlag::O_NOCTTY | OFlag::O_NONBLOCK | OFlag::O_CLOEXEC,
        nix::sys::stat::Mode::empty(),
    )?;
    let _ = nix::sys::termios::tcflush(&fd, nix::sys::termios::FlushArg::TCIFLUSH);
    Ok(fd)
}

/// Serve `sim` on a real serial port `dev` at `baud` (8N1, no flow control), until SIGINT or
/// SIGTERM; the port vanishing is an error. The port's I/O is polled on our own descriptor
/// (see [`crate::live::serial`]), so the signals reach the signalfd.
pub fn run_on_port<S: Simulator>(sim: S, dev: &Path, baud: u32) -> io::Result<()> {
    Ok(serve_on_port(sim, dev, baud)?)
}

/// [`run_on_port`], its error saying what it concerns.
fn serve_on_port<S: Simulator>(mut sim: S, dev: &Path, baud: u32) -> Result<(), LiveError> {
    let sigs = termination_signals()?;
    let settings = LineSettings {
        baud,
        flow: Flow::None,
    };
    let port = open_serial(&dev.to_string_lossy(), &settings)?;
    let fd = OwnedFd::from(port.file.try_clone()?);
    serve_fd(
        &mut sim,
        &fd,
        None,
        &[sigs.as_fd()],
        Line::Port(dev),
        Instant::now(),
    )
    .map(|_| ())
}

#[cfg(test)]
mod port_tests {
    use super::*;
    use crate::live::sim::{AptModel, AptSim};
    use nix::fcntl::{fcntl, FcntlArg};
    use nix::pty::openpty;
    use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
    use std::sync::mpsc;
    use std::time::Duration;

    /// Generous: only reached when something is broken.
    const DEADLINE: Duration = Duration::from_secs(60);

    /// A pseudo-terminal standing in for a serial port: the test holds the master (the far end
    /// of the cable), `run_on_port` opens the slave's path. Returns when the simulator's reply
    /// to HW_REQ_INFO has come back (asked again until then: the port may not be open yet).
    fn serve() -> (OwnedFd, mpsc::Receiver<io::Result<()>>) {
        let pty = openpty(None, None).unwrap();
        let path = nix::unistd::ttyname(&pty.slave).unwrap();
        // Raw before the runner opens it (as it will make it): no echo of what comes early.
        let mut t = tcgetattr(&pty.slave).unwrap();
        cfmakeraw(&mut t);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &t).unwrap();
        let fl = fcntl(&pty.master, FcntlArg::F_GETFL).unwrap();
        let fl = OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK;
        fcntl(&pty.master, FcntlArg::F_SETFL(fl)).unwrap();
        drop(pty.slave);
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let _ = tx.send(run_on_port(AptSim::new(AptModel::Kdc101), &path, 115_200));
        });
        let master = pty.master;
        let t0 = Instant::now();
        let mut got = vec![];
        let mut asked: Option<Instant> = None;
        let mut buf = [0u8; 256];
        while got.len() < 90 {
            assert!(t0.elapsed() < DEADLINE, "no reply: {got:02x?}");
            if got.is_empty() && asked.is_none_or(|t| t.elapsed() > Duration::from_millis(500)) {
                let _ = nix::unistd::write(&master, &[0x05, 0x00, 0x00, 0x00, 0x50, 0x01]);
                asked = Some(Instant::now());
            }
            let mut fds = [PollFd::new(master.as_fd(), PollFlags::POLLIN)];
            let _ = poll(&mut fds, PollTimeout::from(50u16));
            if let Ok(n) = nix::unistd::read(&master, &mut buf) {
                got.extend_from_slice(&buf[..n]);
            }
        }
        assert_eq!(got[..2], [0x06, 0x00], "HW_GET_INFO: {got:02x?}");
        assert_eq!(&got[10..16], b"KDC101");
        (master, rx)
    }

    /// (Its clean end on SIGINT is checked through the binary, `sim apt --port`, in
    /// tests/live.rs: a signal sent to this test process could land in any test's thread.)
    #[test]
    fn run_on_port_serves_a_serial_port_and_fails_when_it_vanishes() {
        let (master, done) = serve();
        drop(master); // the cable is pulled
        let r = done.recv_timeout(DEADLINE).expect("run_on_port hangs");
        assert!(r.is_err(), "a vanished port is an error");
    }
}
