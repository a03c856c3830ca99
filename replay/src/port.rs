//! The line a replay talks on: a serial port (or a simulator's pseudo-terminal, opened as one),
//! or a new pseudo-terminal that a host program opens (`--as device --pty LINK`). A reader
//! thread timestamps what arrives and hands it over a channel, so the sender's clock is never
//! held up by a read.

use aptscope_capture::live::serial::{open_serial, LineSettings, SerialFd};
use aptscope_capture::live::sim::Pty;
use nix::errno::Errno;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use serialport::SerialPort;
use std::fs::File;
use std::io::{self, Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::Arc;
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// How long a read waits before the reader looks at its stop flag again.
const READ_TICK: Duration = Duration::from_millis(20);
/// How long a write may wait for the line to take bytes (flow control, a full buffer).
const WRITE_WAIT: Duration = Duration::from_secs(5);

/// The replay's clock: monotonic ns since the start, and the wall-clock time of the start (for
/// capture timestamps).
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    t0: Instant,
    epoch0_ns: u64,
}

impl Clock {
    /// A clock starting now.
    pub fn start() -> Clock {
        let epoch0_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        Clock {
            t0: Instant::now(),
            epoch0_ns,
        }
    }

    /// ns since the start.
    pub fn now_ns(&self) -> u64 {
        u64::try_from(self.t0.elapsed().as_nanos()).unwrap_or(u64::MAX)
    }

    /// The Unix time (ns) of `t_ns` on this clock.
    pub fn epoch(&self, t_ns: u64) -> u64 {
        self.epoch0_ns.saturating_add(t_ns)
    }
}

/// What the reader thread reports.
#[derive(Debug)]
pub enum RxEvent {
    /// Bytes that arrived at `t_ns` (on the link's [`Clock`]).
    Data {
        /// Arrival time.
        t_ns: u64,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// The other side went away (cable pulled, program closed the port) at `t_ns`.
    Gone {
        /// When it was noticed.
        t_ns: u64,
        /// Why.
        why: String,
    },
}

/// One end of the line: a non-blocking descriptor waited on with `poll` (not the serialport
/// crate's reads, whose `ppoll` unblocks every signal while it waits, so a Ctrl-C meant for the
/// main thread's signalfd would kill the process).
struct Io {
    f: File,
    /// Our copy of a pseudo-terminal's slave until the peer first speaks (so the line stays up
    /// before a program opens it); `None` for a port.
    slave: Option<OwnedFd>,
}

impl Io {
    /// Read what is there within [`READ_TICK`]: `Ok(None)` when nothing came.
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<Option<usize>> {
        let mut fds = [PollFd::new(self.f.as_fd(), PollFlags::POLLIN)];
        match poll(&mut fds, PollTimeout::from(READ_TICK.as_millis() as u16)) {
            Ok(0) | Err(Errno::EINTR) => return Ok(None),
            Ok(_) => {}
            Err(e) => return Err(io::Error::from(e)),
        }
        match self.f.read(buf) {
            Ok(0) => Err(io::Error::new(
                io::ErrorKind::UnexpectedEof,
                "end of file (hung up)",
            )),
            Ok(n) => {
                // The peer is connected: from now on its hang-up ends the line.
                self.slave = None;
                Ok(Some(n))
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(None),
            Err(e) if e.kind() == io::ErrorKind::Interrupted => Ok(None),
            Err(e) if e.raw_os_error() == Some(Errno::EIO as i32) && self.slave.is_some() => {
                // No program has the pseudo-terminal open yet.
                thread::sleep(READ_TICK);
                Ok(None)
            }
            Err(e) if e.raw_os_error() == Some(Errno::EIO as i32) => Err(io::Error::new(
                io::ErrorKind::BrokenPipe,
                "the other side closed the line (I/O error)",
            )),
            Err(e) => Err(e),
        }
    }

    fn write_all(&mut self, mut b: &[u8]) -> io::Result<()> {
        let give_up = Instant::now() + WRITE_WAIT;
        while !b.is_empty() {
            match self.f.write(b) {
                Ok(n) => b = &b[n..],
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if Instant::now() > give_up {
                        return Err(io::Error::new(
                            io::ErrorKind::TimedOut,
                            "the line does not take data (flow control, or nobody reads)",
                        ));
                    }
                    let mut fds = [PollFd::new(self.f.as_fd(), PollFlags::POLLOUT)];
                    let _ = poll(&mut fds, PollTimeout::from(10u8));
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

/// An open line: write with [`Link::send`], receive [`RxEvent`]s from [`Link::rx`].
pub struct Link {
    tx: Io,
    /// The configured port (its settings and exclusive lock last while it is open).
    _port: Option<SerialFd>,
    /// What arrived, timestamped by the reader thread.
    pub rx: Receiver<RxEvent>,
    /// The clock every time of this link is on.
    pub clock: Clock,
    stop: Arc<AtomicBool>,
    reader: Option<JoinHandle<()>>,
    /// The port's name (or the pseudo-terminal's path).
    pub name: String,
    /// The symlink made for the host program and the pseudo-terminal it points at: removed
    /// when the link closes (host gone, SIGINT, SIGTERM), as the tap and the simulators remove
    /// theirs, unless it has been pointed elsewhere since.
    symlink: Option<(PathBuf, PathBuf)>,
}

fn reader(mut io: Io, clock: Clock, tx: Sender<RxEvent>, stop: Arc<AtomicBool>) {
    let mut buf = vec![0u8; 4096];
    while !stop.load(Ordering::Relaxed) {
        match io.read_tick(&mut buf) {
            Ok(None) => {}
            Ok(Some(n)) => {
                let ev = RxEvent::Data {
                    t_ns: clock.now_ns(),
                    bytes: buf[..n].to_vec(),
                };
                if tx.send(ev).is_err() {
                    return;
                }
            }
            Err(e) => {
                let _ = tx.send(RxEvent::Gone {
                    t_ns: clock.now_ns(),
                    why: e.to_string(),
                });
                return;
            }
        }
    }
}

impl Link {
    fn start(tx: Io, rx: Io, port: Option<SerialFd>, name: String) -> Link {
        let clock = Clock::start();
        let stop = Arc::new(AtomicBool::new(false));
        let (s, r) = mpsc::channel();
        let st = stop.clone();
        let reader = thread::Builder::new()
            .name("replay-reader".into())
            .spawn(move || reader(rx, clock, s, st))
            .ok();
        Link {
            tx,
            _port: port,
            rx: r,
            clock,
            stop,
            reader,
            name,
            symlink: None,
        }
    }

    /// Open a serial port (a real one, or a pseudo-terminal such as a simulator's) as the
    /// protocol needs it (8N1 at `line.baud`, with its flow control).
    pub fn open_port(path: &Path, line: LineSettings) -> io::Result<Link> {
        let name = path.to_string_lossy().into_owned();
        let mut port = open_serial(&name, &line)?;
        // Ignore anything sent before we were there.
        let _ = port.port().clear(serialport::ClearBuffer::Input);
        let f = port.file.try_clone()?;
        let w = f.try_clone()?;
        Ok(Link::start(
            Io { f: w, slave: None },
            Io { f, slave: None },
            Some(port),
            name,
        ))
    }

    /// Open a new pseudo-terminal for a host program to open, linked at `link` (an older
    /// symlink there is replaced). Returns the link and the slave's path.
    pub fn open_pty(link: Option<&Path>) -> io::Result<(Link, PathBuf)> {
        let pty = Pty::open()?;
        let (master, slave, path) = pty.into_parts();
        if let Some(l) = link {
            if std::fs::symlink_metadata(l).is_ok_and(|m| m.file_type().is_symlink()) {
                std::fs::remove_file(l)?;
            }
            std::os::unix::fs::symlink(&path, l)?;
        }
        let rfile = File::from(master);
        let wfile = rfile.try_clone()?;
        let name = link.unwrap_or(&path).to_string_lossy().into_owned();
        let mut l = Link::start(
            Io {
                f: wfile,
                slave: None,
            },
            Io { f: rfile, slave },
            None,
            name,
        );
        l.symlink = link.map(|l| (l.to_path_buf(), path.clone()));
        Ok((l, path))
    }

    /// Write `bytes` now.
    pub fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.tx.write_all(bytes)
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        if let Some((link, target)) = &self.symlink {
            // A pseudo-terminal's number is reused: a link left behind would point at another
            // program's terminal.
            if std::fs::read_link(link).is_ok_and(|t| &t == target) {
                let _ = std::fs::remove_file(link);
            }
        }
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.reader.take() {
            let _ = h.join();
        }
    }
}
