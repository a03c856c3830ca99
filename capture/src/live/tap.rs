//! Live taps: a pseudo-terminal man-in-the-middle between a host program and a serial device
//! ([`tap_main`]), and a passive sniff of a Y-cable with two receive-only adapters
//! ([`sniff_main`]). Every chunk is timestamped with its direction, written losslessly to a
//! pcapng (or pcap) capture, and decoded live on a display that may lag (and then skips, and says so).
//!
//! # Threads and policies
//!
//! - **Forwarding** (tap): one thread per direction reads a side and at once writes the bytes to
//!   the other side, then hands a shared copy of the chunk to the recorder and the display. The
//!   two directions never wait on each other (a device holding CTS back stalls host → device
//!   only). Every wait is a poll with a short timeout, so a stop request or a vanished device is
//!   seen within [`TICK`].
//! - **File** (never lossy): chunks go through a queue bounded in bytes ([`FILE_BACKLOG`],
//!   64 MiB: an hour and a half of a saturated 115200-baud line in both directions). Forwarding
//!   never waits on the disk unless that whole backlog is full, i.e. the disk has stalled for a
//!   very long time; then the forwarder waits for room (backpressure: forwarding pauses, the
//!   file stays complete, and [`TapStats::backpressure_waits`] counts it) rather than drop bytes
//!   from the file. Only when writing the file fails (disk full …) are chunks no longer queued;
//!   they are counted in [`TapStats::file_lost`] and the error is reported.
//! - The **writer** merges the two directions by time (a 100 ms window), writes pcapng (or pcap)
//!   blocks and flushes them to the kernel every 256 chunks or every 200 ms (so a follower,
//!   `view --follow`, sees them soon; with a live view, whenever written), so a `kill -9`
//!   leaves a file readable up to its last complete block.
//! - **Display** (lossy): chunks go through a channel of [`DISPLAY_QUEUE`] chunks that the
//!   forwarder only ever `try_send`s into; when a slow terminal lets it fill, chunks are skipped
//!   for display, counted, and a `# display skipped …` line says so (the file still has them).
//! - **Stopping**: SIGINT, SIGTERM and SIGHUP are received through a `signalfd` (Linux; the
//!   signals are blocked in the tap's threads while it runs and the previous mask restored
//!   after), or [`StopHandle::stop`], or the end of [`TapOptions::duration`]. The file is then
//!   finished, and the byte counts per direction are printed and checked against what was
//!   forwarded.
//! - **Device gone** (read/write error or end of file on the port): reported with the time, the
//!   file is flushed (complete and valid at that point); without `reconnect` the tap ends, with
//!   it the tap waits for the device path to come back and carries on in the same file. While
//!   the device is away, what the host writes is read and discarded (not queued up to reach the
//!   device late) and counted in [`TapStats::discarded_h2d`].
#![forbid(unsafe_code)]

use crate::follow::FollowStop;
use crate::live::serial::{self, Flow, LineSettings, SerialFd};
use crate::model::{Chunk, Direction, StreamInfo, Writer};
use crate::open::Format;
use crate::pcap::{PcapNgOut, PcapOut};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Ctx, Format as OutFormat, Pipeline};
use aptscope_dissector::table::Dir;
use aptscope_dissector::units::UnitsOpts;
use nix::errno::Errno;
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};
use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// The longest any thread of a tap waits before looking at stop requests again.
pub const TICK: Duration = Duration::from_millis(100);
/// Bytes the file queue may hold before forwarding waits for the disk (see the module docs).
pub const FILE_BACKLOG: usize = 64 << 20;
/// Chunks the display channel holds before the display skips.
pub const DISPLAY_QUEUE: usize = 4096;
/// How far back the writer waits for the other direction before writing a chunk (merge by time).
const MERGE_WINDOW_NS: u64 = 100_000_000;
/// Flush the file after this many chunks …
const FLUSH_CHUNKS: u64 = 256;
/// … or this long after the last flush.
const FLUSH_EVERY: Duration = Duration::from_millis(200);
/// How often a missing device is looked for (with `reconnect`).
const RETRY_EVERY: Duration = Duration::from_millis(500);
/// Bytes read at once.
const READ_BUF: usize = 4096;

#[derive(Debug, Default)]
struct StopInner {
    flag: AtomicBool,
    m: Mutex<()>,
    cv: Condvar,
}

/// Stops a running tap or sniff from another thread (as Ctrl-C does).
#[derive(Debug, Clone, Default)]
pub struct StopHandle(Arc<StopInner>);

impl StopHandle {
    /// A fresh handle, not stopped.
    pub fn new() -> Self {
        Self::default()
    }

    /// Ask the tap to stop: it finishes the file and returns its statistics.
    pub fn stop(&self) {
        self.0.flag.store(true, Ordering::SeqCst);
        let _g = lock(&self.0.m);
        self.0.cv.notify_all();
    }

    /// Whether a stop was asked for.
    pub fn is_stopped(&self) -> bool {
        self.0.flag.load(Ordering::SeqCst)
    }

    /// Wait up to `d` for a stop (or a [`StopHandle::wake`]); returns whether stopped.
    fn wait(&self, d: Duration) -> bool {
        let g = lock(&self.0.m);
        if self.is_stopped() {
            return true;
        }
        drop(self.0.cv.wait_timeout(g, d));
        self.is_stopped()
    }

    /// Wake waiters without stopping (something else changed).
    fn wake(&self) {
        let _g = lock(&self.0.m);
        self.0.cv.notify_all();
    }
}

/// Lock, ignoring poisoning (a panicked holder leaves plain data behind).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Options of [`tap_main`].
#[derive(Debug, Clone)]
pub struct TapOptions {
    /// The real serial port (`/dev/ttyUSB0`).
    pub device: String,
    /// Where to symlink the pseudo-terminal the host program opens instead (`/tmp/ttyAPT`);
    /// an existing symlink there is replaced, anything else is refused.
    pub link: Option<String>,
    /// The protocol: the default line settings and the live decoder.
    pub proto: Proto,
    /// Baud rate override.
    pub baud: Option<u32>,
    /// Flow control override.
    pub flow: Option<Flow>,
    /// Write the capture here: pcapng, or pcap by the `.pcap` extension (a name without
    /// extension gets pcapng; another extension is refused unless `write_format` says).
    pub write: Option<String>,
    /// The file's format whatever its name says (pcapng or pcap).
    pub write_format: Option<Format>,
    /// Overwrite an existing capture.
    pub force: bool,
    /// `write` is a pipe that already exists (the FIFO Wireshark gives an extcap): it is opened
    /// as it is (never created or truncated), pcapng unless `write_format` says, flushed as soon
    /// as packets are written (a live reader shows them at once), and the tap stops when the
    /// reader closes it ([`TapStats::reader_closed`]).
    pub stream: bool,
    /// When the device disappears, wait for it to come back instead of ending.
    pub reconnect: bool,
    /// No live timeline on standard output.
    pub quiet: bool,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Stop on SIGINT/SIGTERM/SIGHUP (Linux; blocks them in the calling thread while running).
    pub signals: bool,
    /// Stops the tap from another thread.
    pub stop: StopHandle,
    /// Stage or scale for the live timeline's APT motion values (physical units beside raw).
    pub units: UnitsOpts,
    /// A live view follows the `write` file: it is flushed whenever something was written
    /// (every [`TICK`] at most) instead of every 200 ms (set by [`tap_with_view`]).
    pub followed: bool,
}

impl TapOptions {
    /// APT defaults for `device`, symlinked at `link`, no file, signals handled.
    pub fn new(device: impl Into<String>, link: Option<String>) -> Self {
        TapOptions {
            device: device.into(),
            link,
            proto: Proto::Apt,
            baud: None,
            flow: None,
            write: None,
            write_format: None,
            force: false,
            stream: false,
            reconnect: false,
            quiet: false,
            duration: None,
            signals: true,
            stop: StopHandle::new(),
            units: UnitsOpts::default(),
            followed: false,
        }
    }
}

/// Options of [`sniff_main`].
#[derive(Debug, Clone)]
pub struct SniffOptions {
    /// The receive-only adapter on the host's TX line (host → device bytes).
    pub host_tx: String,
    /// The receive-only adapter on the device's TX line (device → host bytes).
    pub device_tx: String,
    /// The protocol: default line settings and live decoder.
    pub proto: Proto,
    /// Baud rate override.
    pub baud: Option<u32>,
    /// Flow control override (normally none: receive-only adapters see no handshake).
    pub flow: Option<Flow>,
    /// Write the capture here: pcapng, or pcap by the `.pcap` extension (a name without
    /// extension gets pcapng; another extension is refused unless `write_format` says).
    pub write: Option<String>,
    /// The file's format whatever its name says (pcapng or pcap).
    pub write_format: Option<Format>,
    /// Overwrite an existing capture.
    pub force: bool,
    /// When an adapter disappears, wait for it to come back instead of ending.
    pub reconnect: bool,
    /// No live timeline on standard output.
    pub quiet: bool,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Stop on SIGINT/SIGTERM/SIGHUP.
    pub signals: bool,
    /// Stops the sniff from another thread.
    pub stop: StopHandle,
    /// Stage or scale for the live timeline's APT motion values (physical units beside raw).
    pub units: UnitsOpts,
    /// A live view follows the `write` file (see [`TapOptions::followed`]).
    pub followed: bool,
}

impl SniffOptions {
    /// APT defaults (baud 115200, no flow control) for the two adapters.
    pub fn new(host_tx: impl Into<String>, device_tx: impl Into<String>) -> Self {
        SniffOptions {
            host_tx: host_tx.into(),
            device_tx: device_tx.into(),
            proto: Proto::Apt,
            baud: None,
            flow: Some(Flow::None),
            write: None,
            write_format: None,
            force: false,
            reconnect: false,
            quiet: false,
            duration: None,
            signals: true,
            stop: StopHandle::new(),
            units: UnitsOpts::default(),
            followed: false,
        }
    }
}

/// A port (or the host side) that disappeared, and when.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Disconnect {
    /// When it was noticed, ns since the Unix epoch.
    pub ts_ns: u64,
    /// Which port.
    pub port: String,
    /// The error.
    pub error: String,
}

/// What a tap or sniff did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TapStats {
    /// Bytes forwarded host → device (sniff: received on the host-TX adapter).
    pub bytes_h2d: u64,
    /// Bytes forwarded device → host (sniff: received on the device-TX adapter).
    pub bytes_d2h: u64,
    /// Chunks forwarded (received).
    pub chunks: u64,
    /// Chunks written to the file.
    pub written: u64,
    /// Host → device bytes written to the file.
    pub written_h2d: u64,
    /// Device → host bytes written to the file.
    pub written_d2h: u64,
    /// Whether a file was written.
    pub file: bool,
    /// The file error, when writing failed.
    pub file_error: Option<String>,
    /// A stream's reader closed it ([`TapOptions::stream`]): the normal end of a capture
    /// into Wireshark; `file_error` says so too.
    pub reader_closed: bool,
    /// Bytes not written to the file because writing it had failed.
    pub file_lost: u64,
    /// Times forwarding waited because the file's backlog was full.
    pub backpressure_waits: u64,
    /// Bytes skipped by the live display (a slow terminal); the file has them.
    pub display_skipped: u64,
    /// Bytes read from one side that could not be delivered to the other (it vanished, or the
    /// tap was stopped while the other side was not accepting them); not in the file.
    pub undelivered: u64,
    /// Bytes the host wrote while the device was away (discarded, not in the file).
    pub discarded_h2d: u64,
    /// Ports that disappeared.
    pub disconnects: Vec<Disconnect>,
}

impl TapStats {
    /// Whether the file holds exactly what was forwarded, per direction (true without a file).
    pub fn file_matches(&self) -> bool {
        !self.file
            || (self.file_error.is_none()
                && self.written_h2d == self.bytes_h2d
                && self.written_d2h == self.bytes_d2h
                && self.written == self.chunks)
    }

    /// A human summary, one line per fact.
    pub fn summary(&self, what: &str) -> String {
        let mut s = format!(
            "{what}: host → device {} bytes, device → host {} bytes, {} chunks",
            self.bytes_h2d, self.bytes_d2h, self.chunks
        );
        if self.file {
            s += &format!(
                "\n{what}: file: host → device {} bytes, device → host {} bytes, {} chunks: {}",
                self.written_h2d,
                self.written_d2h,
                self.written,
                if self.file_matches() {
                    "matches what was forwarded".to_string()
                } else if self.reader_closed {
                    "its reader closed it".to_string()
                } else {
                    format!(
                        "MISMATCH ({} bytes lost{})",
                        self.file_lost,
                        self.file_error
                            .as_ref()
                            .map(|e| format!(", error: {e}"))
                            .unwrap_or_default()
                    )
                }
            );
        }
        for (n, label) in [
            (self.display_skipped, "bytes skipped by the display"),
            (self.backpressure_waits, "waits for the disk"),
            (self.undelivered, "bytes read but not delivered"),
            (self.discarded_h2d, "host bytes discarded while away"),
        ] {
            if n > 0 {
                s += &format!("\n{what}: {n} {label}");
            }
        }
        for d in &self.disconnects {
            s += &format!(
                "\n{what}: {} gone at {}: {}",
                d.port,
                clock_time(d.ts_ns),
                d.error
            );
        }
        s
    }
}

/// `HH:MM:SS.mmm UTC` of a time in ns since the epoch.
fn clock_time(ns: u64) -> String {
    let ms = ns / 1_000_000;
    let s = ms / 1000;
    format!(
        "{:02}:{:02}:{:02}.{:03} UTC",
        (s / 3600) % 24,
        (s / 60) % 60,
        s % 60,
        ms % 1000
    )
}

/// Wall-clock ns since the epoch, advancing monotonically from the start.
#[derive(Debug, Clone, Copy)]
struct Clock {
    base_ns: u64,
    t0: Instant,
}

impl Clock {
    fn new() -> Self {
        Clock {
            base_ns: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(0),
            t0: Instant::now(),
        }
    }
    fn now(&self) -> u64 {
        self.base_ns + self.t0.elapsed().as_nanos() as u64
    }
}

// ---------------------------------------------------------------------------------------------
// Ports

/// One handle on a side, used by one thread in one direction.
trait Port: Send {
    /// Read what arrives within [`TICK`]: `Ok(0)` when nothing did; an error when the side is
    /// gone (end of file is `UnexpectedEof`).
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize>;
    /// Write what the side accepts within [`TICK`]: `Ok(0)` when it accepted nothing.
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize>;
}

fn eof() -> io::Error {
    io::Error::new(io::ErrorKind::UnexpectedEof, "end of file (hung up)")
}

fn transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted | io::ErrorKind::TimedOut
    )
}

/// Wait up to `timeout` for `ev` on `fd`: whether something happened (readiness, hang-up or
/// error, which the following read or write reports).
fn wait_fd(fd: BorrowedFd<'_>, ev: PollFlags, timeout: Duration) -> io::Result<bool> {
    let ms = u16::try_from(timeout.as_millis()).unwrap_or(u16::MAX);
    let mut fds = [PollFd::new(fd, ev)];
    match poll(&mut fds, PollTimeout::from(ms)) {
        Ok(0) | Err(Errno::EINTR) => Ok(false),
        Ok(_) => Ok(true),
        Err(e) => Err(e.into()),
    }
}

/// A non-blocking file descriptor (the pty master; any fd in tests), waited on with poll.
struct FdPort(File);

impl FdPort {
    fn new(fd: OwnedFd) -> io::Result<Self> {
        let fl = fcntl(&fd, FcntlArg::F_GETFL)?;
        fcntl(
            &fd,
            FcntlArg::F_SETFL(OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK),
        )?;
        Ok(FdPort(File::from(fd)))
    }
    fn try_clone(&self) -> io::Result<Self> {
        Ok(FdPort(self.0.try_clone()?))
    }
}

impl Port for FdPort {
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if !wait_fd(self.0.as_fd(), PollFlags::POLLIN, TICK)? {
            return Ok(0);
        }
        match self.0.read(buf) {
            Ok(0) => Err(eof()),
            Ok(n) => Ok(n),
            Err(e) if transient(&e) => Ok(0),
            Err(e) => Err(e),
        }
    }
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize> {
        if !wait_fd(self.0.as_fd(), PollFlags::POLLOUT, TICK)? {
            return Ok(0);
        }
        match self.0.write(buf) {
            Ok(n) => Ok(n),
            Err(e) if transient(&e) => Ok(0),
            Err(e) => Err(e),
        }
    }
}

/// A real serial port: our polled descriptor (see [`crate::live::serial`]), and the configured
/// port it belongs to, kept open as long as either handle is.
struct SerialPort {
    fd: FdPort,
    hold: Arc<Mutex<SerialFd>>,
}

impl Port for SerialPort {
    fn read_tick(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.fd.read_tick(buf)
    }
    fn write_tick(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.fd.write_tick(buf)
    }
}

/// The device side: a read handle and a write handle.
type DevicePair = (Box<dyn Port>, Box<dyn Port>);

/// Open a serial port (exclusively) with `settings`.
fn open_serial(path: &str, settings: &LineSettings) -> io::Result<SerialPort> {
    let s = serial::open_serial(path, settings)?;
    Ok(SerialPort {
        fd: FdPort::new(OwnedFd::from(s.file.try_clone()?))?,
        hold: Arc::new(Mutex::new(s)),
    })
}

fn open_device(path: &str, settings: &LineSettings) -> io::Result<DevicePair> {
    let r = open_serial(path, settings)?;
    let w = SerialPort {
        fd: r.fd.try_clone()?,
        hold: r.hold.clone(),
    };
    Ok((Box::new(r), Box::new(w)))
}

/// The host side: a raw-mode pseudo-terminal whose slave the host program opens.
struct HostPty {
    master: FdPort,
    /// Held open so the master never sees a hang-up when the host program closes and reopens
    /// the slave, and so the raw settings stay.
    _slave: OwnedFd,
    slave_path: PathBuf,
    link: Option<PathBuf>,
}

impl HostPty {
    fn create(link: Option<&str>) -> io::Result<HostPty> {
        use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};
        let pty = nix::pty::openpty(None, None)?;
        let mut t = tcgetattr(&pty.slave)?;
        cfmakeraw(&mut t);
        tcsetattr(&pty.slave, SetArg::TCSANOW, &t)?;
        let slave_path = nix::unistd::ttyname(&pty.slave)?;
        let link = match link {
            Some(l) => {
                let l = PathBuf::from(l);
                match std::fs::symlink_metadata(&l) {
                    Ok(m) if m.file_type().is_symlink() => std::fs::remove_file(&l)?,
                    Ok(_) => {
                        return Err(io::Error::new(
                            io::ErrorKind::AlreadyExists,
                            format!("{}: exists and is not a symlink", l.display()),
                        ))
                    }
                    Err(_) => {}
                }
                std::os::unix::fs::symlink(&slave_path, &l)
                    .map_err(|e| io::Error::new(e.kind(), format!("{}: {e}", l.display())))?;
                Some(l)
            }
            None => None,
        };
        Ok(HostPty {
            master: FdPort::new(pty.master)?,
            _slave: pty.slave,
            slave_path,
            link,
        })
    }
}

impl Drop for HostPty {
    fn drop(&mut self) {
        if let Some(l) = &self.link {
            if std::fs::read_link(l).is_ok_and(|t| t == self.slave_path) {
                let _ = std::fs::remove_file(l);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Signals

#[cfg(target_os = "linux")]
mod signals {
    use super::{wait_fd, Duration};
    use nix::poll::PollFlags;
    use nix::sys::signal::{SigSet, SigmaskHow, Signal};
    use nix::sys::signalfd::{SfdFlags, SignalFd};
    use std::io;
    use std::os::fd::AsFd;

    /// SIGINT, SIGTERM and SIGHUP, blocked in this thread (and the threads it starts) and read
    /// from a signalfd; the previous mask comes back on drop.
    pub struct Signals {
        fd: SignalFd,
        old: SigSet,
    }

    impl Signals {
        pub fn install() -> io::Result<Signals> {
            let mut set = SigSet::empty();
            for s in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
                set.add(s);
            }
            let old = set.thread_swap_mask(SigmaskHow::SIG_BLOCK)?;
            match SignalFd::with_flags(&set, SfdFlags::SFD_NONBLOCK | SfdFlags::SFD_CLOEXEC) {
                Ok(fd) => Ok(Signals { fd, old }),
                Err(e) => {
                    let _ = old.thread_set_mask();
                    Err(e.into())
                }
            }
        }

        /// A signal received within `timeout`, by name.
        pub fn wait(&self, timeout: Duration) -> Option<String> {
            if !wait_fd(self.fd.as_fd(), PollFlags::POLLIN, timeout).unwrap_or(false) {
                return None;
            }
            self.take()
        }

        fn take(&self) -> Option<String> {
            let si = self.fd.read_signal().ok()??;
            Some(
                Signal::try_from(si.ssi_signo as i32)
                    .map(|s| s.as_str().to_string())
                    .unwrap_or_else(|_| format!("signal {}", si.ssi_signo)),
            )
        }
    }

    impl Drop for Signals {
        fn drop(&mut self) {
            // Consume what is pending so unblocking does not deliver it (and kill us).
            while self.take().is_some() {}
            let _ = self.old.thread_set_mask();
        }
    }
}

#[cfg(not(target_os = "linux"))]
mod signals {
    use super::Duration;
    use std::io;

    /// No signalfd here: stop with the duration or a stop handle.
    pub struct Signals;

    impl Signals {
        pub fn install() -> io::Result<Signals> {
            Ok(Signals)
        }
        pub fn wait(&self, timeout: Duration) -> Option<String> {
            let _ = nix::poll::poll(
                &mut [],
                nix::poll::PollTimeout::from(timeout.as_millis() as u16),
            );
            None
        }
    }
}

use signals::Signals;

// ---------------------------------------------------------------------------------------------
// Recording

/// A captured chunk, shared between the file and the display.
#[derive(Debug)]
struct Rec {
    ts: u64,
    dir: Direction,
    bytes: Vec<u8>,
}

enum QItem {
    Chunk(Arc<Rec>),
    /// Write everything queued and flush (a device went away).
    Sync,
}

#[derive(Default)]
struct QState {
    q: VecDeque<QItem>,
    bytes: usize,
    closed: bool,
    failed: bool,
}

/// The file's queue, bounded in bytes.
struct FileQueue {
    st: Mutex<QState>,
    not_empty: Condvar,
    not_full: Condvar,
    budget: usize,
    waits: AtomicU64,
    lost: AtomicU64,
}

impl FileQueue {
    fn new(budget: usize) -> Self {
        FileQueue {
            st: Mutex::new(QState::default()),
            not_empty: Condvar::new(),
            not_full: Condvar::new(),
            budget,
            waits: AtomicU64::new(0),
            lost: AtomicU64::new(0),
        }
    }

    fn push(&self, item: QItem) {
        let len = match &item {
            QItem::Chunk(r) => r.bytes.len(),
            QItem::Sync => 0,
        };
        let mut st = lock(&self.st);
        let mut waited = false;
        while !st.failed && st.bytes > 0 && st.bytes + len > self.budget {
            if !waited {
                self.waits.fetch_add(1, Ordering::Relaxed);
                waited = true;
            }
            st = match self.not_full.wait_timeout(st, TICK) {
                Ok((g, _)) => g,
                Err(e) => e.into_inner().0,
            };
        }
        if st.failed {
            self.lost.fetch_add(len as u64, Ordering::Relaxed);
            return;
        }
        st.bytes += len;
        st.q.push_back(item);
        self.not_empty.notify_one();
    }

    /// Everything queued (waiting up to `timeout` for something), and whether the queue is
    /// closed and now empty.
    fn pop_all(&self, timeout: Duration) -> (Vec<QItem>, bool) {
        let mut st = lock(&self.st);
        if st.q.is_empty() && !st.closed {
            st = match self.not_empty.wait_timeout(st, timeout) {
                Ok((g, _)) => g,
                Err(e) => e.into_inner().0,
            };
        }
        let items: Vec<QItem> = st.q.drain(..).collect();
        st.bytes = 0;
        self.not_full.notify_all();
        (items, st.closed)
    }

    fn close(&self) {
        lock(&self.st).closed = true;
        self.not_empty.notify_all();
    }

    fn fail(&self) {
        let mut st = lock(&self.st);
        st.failed = true;
        for it in st.q.drain(..) {
            if let QItem::Chunk(r) = it {
                self.lost.fetch_add(r.bytes.len() as u64, Ordering::Relaxed);
            }
        }
        st.bytes = 0;
        self.not_full.notify_all();
    }
}

/// A buffered file whose buffer the writer thread can flush while the pcapng writer owns it.
#[derive(Clone)]
struct SharedFile(Arc<Mutex<BufWriter<File>>>);

impl Write for SharedFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        lock(&self.0).write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        lock(&self.0).write_all(buf)
    }
    fn flush(&mut self) -> io::Result<()> {
        lock(&self.0).flush()
    }
}

/// The capture file: a pcapng or pcap writer (one stream) over a [`SharedFile`].
struct FileSink {
    out: Box<dyn Writer + Send>,
    file: SharedFile,
    /// A stream ([`TapOptions::stream`]): the pipe, to see its reader go away.
    stream: Option<File>,
    /// Flushed whenever something was written (a stream, or a file a live view follows).
    eager: bool,
}

impl FileSink {
    /// The capture's format (checked before any port is opened). Streaming formats only:
    /// every block is whole once flushed, so a killed tap leaves a readable file. MCAP needs
    /// its footer (and text formats lose the times): convert.
    fn format(path: &str, forced: Option<Format>) -> io::Result<Format> {
        match Format::for_writing(path, forced)? {
            f @ (Format::PcapNg | Format::Pcap) => Ok(f),
            other => Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "{path}: the tap writes pcapng or pcap (readable up to the last block if \
                     it is killed), not {}; record a .pcapng and `aptscope convert` it",
                    other.name()
                ),
            )),
        }
    }

    /// Create `path` in `format` (refusing to overwrite unless `force`, as
    /// [`crate::open::create`] does; built here rather than with it to be able to flush
    /// periodically) and declare `stream`.
    fn create(
        path: &str,
        format: Format,
        force: bool,
        stream: &StreamInfo,
    ) -> io::Result<FileSink> {
        let f = if force {
            File::create(path)
        } else {
            File::options().write(true).create_new(true).open(path)
        }
        .map_err(|e| {
            if e.kind() == io::ErrorKind::AlreadyExists {
                io::Error::new(
                    e.kind(),
                    format!("{path} exists (use --force to overwrite)"),
                )
            } else {
                io::Error::new(e.kind(), format!("{path}: {e}"))
            }
        })?;
        FileSink::over(f, format, stream, false)
    }

    /// The sink `opts` ask for: the pipe of a stream, else a file created, flushed as it is
    /// written when a live view follows it.
    fn for_opts(
        path: &str,
        format: Format,
        (stream, force, followed): (bool, bool, bool),
        info: &StreamInfo,
    ) -> io::Result<FileSink> {
        let mut sink = if stream {
            FileSink::open_stream(path, format, info)?
        } else {
            FileSink::create(path, format, force, info)?
        };
        sink.eager |= followed;
        Ok(sink)
    }

    /// Open the existing pipe `path` (waiting for its reader, as opening a FIFO does) and
    /// declare `stream` in `format`.
    fn open_stream(path: &str, format: Format, stream: &StreamInfo) -> io::Result<FileSink> {
        use std::os::unix::fs::FileTypeExt;
        let t = std::fs::metadata(path)
            .map_err(|e| io::Error::new(e.kind(), format!("{path}: {e}")))?
            .file_type();
        // Written from its start without truncating: only right for a pipe (or a terminal).
        if !(t.is_fifo() || t.is_char_device() || t.is_socket()) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{path}: not a pipe (a stream goes into an existing FIFO)"),
            ));
        }
        let f = File::options()
            .write(true)
            .open(path)
            .map_err(|e| io::Error::new(e.kind(), format!("{path}: {e}")))?;
        FileSink::over(f, format, stream, true)
    }

    fn over(f: File, format: Format, stream: &StreamInfo, live: bool) -> io::Result<FileSink> {
        let pipe = if live { Some(f.try_clone()?) } else { None };
        let file = SharedFile(Arc::new(Mutex::new(BufWriter::with_capacity(1 << 16, f))));
        let mut out: Box<dyn Writer + Send> = match format {
            Format::Pcap => Box::new(PcapOut::new(file.clone())?),
            _ => Box::new(PcapNgOut::new(file.clone())?),
        };
        out.stream(stream)?;
        let mut sink = FileSink {
            out,
            file,
            stream: pipe,
            eager: live,
        };
        sink.flush()?;
        Ok(sink)
    }

    /// Whether the stream's reader has closed it (a pipe's write end polls as an error then).
    fn reader_gone(&self) -> bool {
        let Some(p) = &self.stream else {
            return false;
        };
        let mut fds = [PollFd::new(p.as_fd(), PollFlags::POLLOUT)];
        matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
            && fds[0]
                .revents()
                .is_some_and(|r| r.intersects(PollFlags::POLLERR | PollFlags::POLLHUP))
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// Two per-direction queues merged by time: a chunk is written once the other direction has a
/// later one, or once it is older than the merge window.
#[derive(Default)]
struct Merger {
    lanes: [VecDeque<Arc<Rec>>; 2],
}

impl Merger {
    fn push(&mut self, r: Arc<Rec>) {
        let i = usize::from(r.dir == Direction::DeviceToHost);
        self.lanes[i].push_back(r);
    }
    /// The next chunk in time order whose time is at most `horizon` (`None`: any).
    fn pop(&mut self, horizon: Option<u64>) -> Option<Arc<Rec>> {
        let i = match (self.lanes[0].front(), self.lanes[1].front()) {
            (Some(a), Some(b)) => usize::from(b.ts < a.ts),
            (Some(a), None) if horizon.is_none_or(|h| a.ts <= h) => 0,
            (None, Some(b)) if horizon.is_none_or(|h| b.ts <= h) => 1,
            _ => return None,
        };
        self.lanes[i].pop_front()
    }
}

#[derive(Default)]
struct WriterOut {
    written: u64,
    h2d: u64,
    d2h: u64,
    error: Option<String>,
    reader_closed: bool,
}

/// Write what the queue brings until it is closed. A stream sink is flushed whenever something
/// was written, and its reader going away stops the whole tap through `stop` (nothing left to
/// record into).
fn writer_loop(q: &FileQueue, mut sink: FileSink, clock: Clock, stop: &StopHandle) -> WriterOut {
    let mut out = WriterOut::default();
    let mut merger = Merger::default();
    let mut since_flush = 0u64;
    let mut last_flush = Instant::now();
    let write = |sink: &mut FileSink, r: &Rec, out: &mut WriterOut| -> io::Result<()> {
        sink.out.chunk(&Chunk {
            ts_ns: Some(r.ts),
            dir: r.dir,
            stream: 0,
            bytes: &r.bytes,
        })?;
        out.written += 1;
        match r.dir {
            Direction::HostToDevice => out.h2d += r.bytes.len() as u64,
            _ => out.d2h += r.bytes.len() as u64,
        }
        Ok(())
    };
    let result = (|| -> io::Result<()> {
        loop {
            let (items, closed) = q.pop_all(TICK);
            let mut sync = closed;
            for it in items {
                match it {
                    QItem::Chunk(r) => merger.push(r),
                    QItem::Sync => sync = true,
                }
            }
            let horizon = if sync {
                None
            } else {
                Some(clock.now().saturating_sub(MERGE_WINDOW_NS))
            };
            while let Some(r) = merger.pop(horizon) {
                write(&mut sink, &r, &mut out)?;
                since_flush += 1;
            }
            if sync
                || since_flush >= FLUSH_CHUNKS
                || (since_flush > 0 && (sink.eager || last_flush.elapsed() >= FLUSH_EVERY))
            {
                sink.flush()?;
                since_flush = 0;
                last_flush = Instant::now();
            }
            // Seen at once even when nothing is being written (a quiet line).
            if sink.reader_gone() {
                return Err(io::Error::new(
                    io::ErrorKind::BrokenPipe,
                    "the reader closed the pipe",
                ));
            }
            if closed {
                return sink.out.finish();
            }
        }
    })();
    if let Err(e) = result {
        // (A pcapng writer's error may wrap the broken pipe: the pipe itself says.)
        if sink.stream.is_some() && (e.kind() == io::ErrorKind::BrokenPipe || sink.reader_gone()) {
            out.reader_closed = true;
            stop.stop();
        }
        q.fail();
        for lane in &merger.lanes {
            for r in lane {
                q.lost.fetch_add(r.bytes.len() as u64, Ordering::Relaxed);
            }
        }
        out.error = Some(e.to_string());
    }
    out
}

/// What all threads share.
struct Shared {
    clock: Clock,
    stop: StopHandle,
    fwd: [AtomicU64; 2],
    chunks: AtomicU64,
    undelivered: AtomicU64,
    discarded_h2d: AtomicU64,
    file: Option<FileQueue>,
    display: Option<SyncSender<Arc<Rec>>>,
    display_skipped: AtomicU64,
    display_done: AtomicBool,
    disconnects: Mutex<Vec<Disconnect>>,
}

impl Shared {
    fn new(stop: StopHandle, file: bool, display: Option<SyncSender<Arc<Rec>>>) -> Shared {
        Shared {
            clock: Clock::new(),
            stop,
            fwd: [AtomicU64::new(0), AtomicU64::new(0)],
            chunks: AtomicU64::new(0),
            undelivered: AtomicU64::new(0),
            discarded_h2d: AtomicU64::new(0),
            file: file.then(|| FileQueue::new(FILE_BACKLOG)),
            display,
            display_skipped: AtomicU64::new(0),
            display_done: AtomicBool::new(false),
            disconnects: Mutex::new(vec![]),
        }
    }

    /// Hand a chunk just read to the display, before it is forwarded: the reply it causes can
    /// then never reach the display first. Never blocks (a full display skips, and says so).
    fn show(&self, rec: &Arc<Rec>) {
        if let Some(tx) = &self.display {
            match tx.try_send(rec.clone()) {
                Ok(()) => {}
                Err(TrySendError::Full(r) | TrySendError::Disconnected(r)) => {
                    self.display_skipped
                        .fetch_add(r.bytes.len() as u64, Ordering::Relaxed);
                }
            }
        }
    }

    /// Count a chunk that crossed and hand it to the file (which blocks only when its whole
    /// backlog is full).
    fn record(&self, rec: Arc<Rec>) {
        let i = usize::from(rec.dir == Direction::DeviceToHost);
        self.fwd[i].fetch_add(rec.bytes.len() as u64, Ordering::Relaxed);
        self.chunks.fetch_add(1, Ordering::Relaxed);
        if let Some(q) = &self.file {
            q.push(QItem::Chunk(rec));
        }
    }

    fn disconnect(&self, ts_ns: u64, port: &str, error: &io::Error) {
        let d = Disconnect {
            ts_ns,
            port: port.to_string(),
            error: error.to_string(),
        };
        crate::note!(
            "aptscope: {} gone at {} (+{:.3} s): {}",
            d.port,
            clock_time(ts_ns),
            ts_ns.saturating_sub(self.clock.base_ns) as f64 / 1e9,
            d.error
        );
        lock(&self.disconnects).push(d);
        if let Some(q) = &self.file {
            q.push(QItem::Sync);
        }
    }

    fn stats(&self, w: Option<WriterOut>) -> TapStats {
        let file = self.file.is_some();
        let w = w.unwrap_or_default();
        TapStats {
            bytes_h2d: self.fwd[0].load(Ordering::Relaxed),
            bytes_d2h: self.fwd[1].load(Ordering::Relaxed),
            chunks: self.chunks.load(Ordering::Relaxed),
            written: w.written,
            written_h2d: w.h2d,
            written_d2h: w.d2h,
            file,
            file_error: w.error,
            reader_closed: w.reader_closed,
            file_lost: self
                .file
                .as_ref()
                .map_or(0, |q| q.lost.load(Ordering::Relaxed)),
            backpressure_waits: self
                .file
                .as_ref()
                .map_or(0, |q| q.waits.load(Ordering::Relaxed)),
            display_skipped: self.display_skipped.load(Ordering::Relaxed),
            undelivered: self.undelivered.load(Ordering::Relaxed),
            discarded_h2d: self.discarded_h2d.load(Ordering::Relaxed),
            disconnects: lock(&self.disconnects).clone(),
        }
    }
}

/// The live timeline: decodes what the display channel brings, writes lines to `out`.
fn display_loop(
    rx: Receiver<Arc<Rec>>,
    (proto, units): (Proto, UnitsOpts),
    out: &mut dyn Write,
    sh: &Shared,
) {
    let mut p = Pipeline::new(Some(proto), OutFormat::Text);
    p.set_units(units);
    let mut broken = false;
    let mut reported = 0u64;
    let mut emit = |line: &str| -> io::Result<()> { writeln!(out, "{line}") };
    let mut show = |r: &Rec, p: &mut Pipeline, broken: &mut bool, reported: &mut u64| {
        if *broken {
            return;
        }
        let skipped = sh.display_skipped.load(Ordering::Relaxed);
        if skipped > *reported {
            let n = skipped - *reported;
            *reported = skipped;
            if emit(&format!(
                "# display skipped {n} bytes (terminal too slow); the capture file has them"
            ))
            .is_err()
            {
                *broken = true;
                return;
            }
        }
        let ctx = Ctx {
            stream: 0,
            dir: r.dir.dir(),
            ts_ns: Some(r.ts),
        };
        if p.push_chunk(ctx, &r.bytes, &mut emit).is_err() {
            *broken = true;
        }
        // Live, a host's read is its write: show an Elliptec command sent without terminator
        // now, not when the host next writes (a module that never answers would hide it).
        if ctx.dir == Some(Dir::HostToDevice) && p.cut(0, Dir::HostToDevice, &mut emit).is_err() {
            *broken = true;
        }
    };
    loop {
        match rx.recv_timeout(TICK) {
            Ok(r) => show(&r, &mut p, &mut broken, &mut reported),
            Err(RecvTimeoutError::Timeout) => {
                if sh.display_done.load(Ordering::SeqCst) {
                    while let Ok(r) = rx.try_recv() {
                        show(&r, &mut p, &mut broken, &mut reported);
                    }
                    break;
                }
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    if !broken {
        let _ = p.finish(&mut emit);
    }
    let _ = out.flush();
}

/// Standard output, flushed line by line (a live display).
struct LineOut(io::Stdout);

impl Write for LineOut {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut l = self.0.lock();
        l.write_all(buf)?;
        if buf.ends_with(b"\n") {
            l.flush()?;
        }
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        self.0.flush()
    }
}

// ---------------------------------------------------------------------------------------------
// Forwarding

enum FwdEnd {
    /// Asked to stop (or the session ended on the other direction).
    Stopped,
    /// The read side failed.
    SrcGone(u64, io::Error),
    /// The write side failed.
    DstGone(u64, io::Error),
}

/// Read `src`, write each chunk whole to `dst` (when there is one: a sniff has none), record
/// what was delivered. Returns when stopped, when `end` is set, or when a side fails.
fn forward(
    src: &mut dyn Port,
    mut dst: Option<&mut dyn Port>,
    dir: Direction,
    sh: &Shared,
    end: &AtomicBool,
) -> FwdEnd {
    let mut buf = vec![0u8; READ_BUF];
    let stopped = || sh.stop.is_stopped() || end.load(Ordering::SeqCst);
    loop {
        if stopped() {
            return FwdEnd::Stopped;
        }
        let n = match src.read_tick(&mut buf) {
            Ok(0) => continue,
            Ok(n) => n,
            Err(e) => return FwdEnd::SrcGone(sh.clock.now(), e),
        };
        let rec = Arc::new(Rec {
            ts: sh.clock.now(),
            dir,
            bytes: buf[..n].to_vec(),
        });
        sh.show(&rec);
        let mut done = 0;
        let mut failure = None;
        if let Some(d) = dst.as_deref_mut() {
            while done < n {
                match d.write_tick(&buf[done..n]) {
                    Ok(0) if stopped() => {
                        failure = Some(FwdEnd::Stopped);
                        break;
                    }
                    Ok(k) => done += k,
                    Err(e) => {
                        failure = Some(FwdEnd::DstGone(sh.clock.now(), e));
                        break;
                    }
                }
            }
        } else {
            done = n;
        }
        if done == n {
            sh.record(rec);
        } else if done > 0 {
            sh.record(Arc::new(Rec {
                ts: rec.ts,
                dir,
                bytes: buf[..done].to_vec(),
            }));
        }
        if let Some(f) = failure {
            sh.undelivered
                .fetch_add((n - done) as u64, Ordering::Relaxed);
            return f;
        }
    }
}

/// Wait until `end` is set, a stop is asked for, a signal arrives or the deadline passes.
fn supervise(sh: &Shared, signals: Option<&Signals>, deadline: Option<Instant>, end: &AtomicBool) {
    loop {
        if end.load(Ordering::SeqCst) || sh.stop.is_stopped() {
            return;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            sh.stop.stop();
            return;
        }
        match signals {
            Some(s) => {
                if let Some(sig) = s.wait(TICK) {
                    sh.stop.stop();
                    crate::note!("aptscope: {sig}: stopping");
                    return;
                }
            }
            None => {
                sh.stop.wait(TICK);
            }
        }
    }
}

/// Start the file writer and display threads in `scope`, run `body`, then close them and
/// collect the statistics.
fn run_recorded<'s, 'e: 's>(
    scope: &'s thread::Scope<'s, 'e>,
    sh: &'e Shared,
    sink: Option<FileSink>,
    display: Option<DisplayTo>,
    decode: (Proto, UnitsOpts),
    body: impl FnOnce() -> io::Result<()>,
) -> io::Result<TapStats> {
    let clock = sh.clock;
    let writer = match (sink, &sh.file) {
        (Some(sink), Some(q)) => Some(scope.spawn(move || writer_loop(q, sink, clock, &sh.stop))),
        _ => None,
    };
    let disp =
        display.map(|(rx, mut out)| scope.spawn(move || display_loop(rx, decode, &mut *out, sh)));
    let r = body();
    if let Some(q) = &sh.file {
        q.close();
    }
    sh.display_done.store(true, Ordering::SeqCst);
    let w = writer.map(|h| {
        h.join().unwrap_or_else(|_| WriterOut {
            error: Some("the file writer panicked".into()),
            ..WriterOut::default()
        })
    });
    if let Some(d) = disp {
        let _ = d.join();
    }
    r.map(|()| sh.stats(w))
}

/// The display's channel and where it writes.
type DisplayTo = (Receiver<Arc<Rec>>, Box<dyn Write + Send>);

/// What a tap or sniff records into: the shared state, the file, the display's channel.
struct Recording {
    sh: Arc<Shared>,
    sink: Option<FileSink>,
    disp_rx: Option<Receiver<Arc<Rec>>>,
}

impl Recording {
    fn new(stop: StopHandle, quiet: bool, sink: Option<FileSink>) -> Recording {
        let (tx, rx) = if quiet {
            (None, None)
        } else {
            let (tx, rx) = mpsc::sync_channel(DISPLAY_QUEUE);
            (Some(tx), Some(rx))
        };
        Recording {
            sh: Arc::new(Shared::new(stop, sink.is_some(), tx)),
            sink,
            disp_rx: rx,
        }
    }

    /// The display's channel and where it writes (standard output unless `out`).
    fn display(
        rx: Option<Receiver<Arc<Rec>>>,
        out: Option<Box<dyn Write + Send>>,
    ) -> Option<DisplayTo> {
        let out = out.unwrap_or_else(|| Box::new(LineOut(io::stdout())));
        rx.map(|rx| (rx, out))
    }
}

/// Run `f` with the stop signals handled (when `handle`), then print the statistics as `what`.
fn run_signalled(
    handle: bool,
    what: &str,
    f: impl FnOnce(Option<&Signals>) -> io::Result<TapStats>,
) -> io::Result<TapStats> {
    let signals = if handle {
        Some(Signals::install()?)
    } else {
        None
    };
    let stats = f(signals.as_ref())?;
    drop(signals);
    crate::note!("{}", stats.summary(what));
    Ok(stats)
}

/// Run a tap: create the pseudo-terminal (symlinked at `opts.link`), open the device, forward
/// both ways until stopped (signal, [`StopHandle`], duration) or the device disappears (unless
/// `reconnect`), write the capture, show the timeline; print and return the statistics.
pub fn tap_main(opts: TapOptions) -> io::Result<TapStats> {
    Tap::new(opts)?.run(None)
}

/// A tap set up (device open, pseudo-terminal and file created) and ready to run.
struct Tap {
    opts: TapOptions,
    settings: LineSettings,
    device: Option<DevicePair>,
    host: HostPty,
    rec: Recording,
}

impl Tap {
    fn new(opts: TapOptions) -> io::Result<Tap> {
        let settings = LineSettings::for_proto(opts.proto, opts.baud, opts.flow);
        let format = match (&opts.write, opts.stream) {
            // A pipe's name says nothing about what goes through it.
            (Some(_), true) => Some(opts.write_format.unwrap_or(Format::PcapNg)),
            (p, _) => p
                .as_deref()
                .map(|p| FileSink::format(p, opts.write_format))
                .transpose()?,
        };
        let device = match open_device(&opts.device, &settings) {
            Ok(d) => Some(d),
            Err(e) if opts.reconnect => {
                crate::note!("aptscope tap: {e}; waiting for it");
                None
            }
            Err(e) => return Err(e),
        };
        let host = HostPty::create(opts.link.as_deref())?;
        let info = StreamInfo {
            id: 0,
            name: opts.device.clone(),
            settings: Some(settings.to_string()),
        };
        let format = format.unwrap_or(Format::PcapNg);
        let sink = match &opts.write {
            Some(p) => Some(FileSink::for_opts(
                p,
                format,
                (opts.stream, opts.force, opts.followed),
                &info,
            )?),
            None => None,
        };
        crate::note!(
            "aptscope tap: host side {}{} ⇄ device {} ({settings}){}",
            host.slave_path.display(),
            host.link
                .as_ref()
                .map(|l| format!(" (link {})", l.display()))
                .unwrap_or_default(),
            opts.device,
            opts.write
                .as_ref()
                .map(|w| format!(", writing {w}"))
                .unwrap_or_default()
        );
        let rec = Recording::new(opts.stop.clone(), opts.quiet, sink);
        Ok(Tap {
            opts,
            settings,
            device,
            host,
            rec,
        })
    }

    /// Run until stopped, with the timeline going to `display` (standard output when `None`).
    fn run(self, display: Option<Box<dyn Write + Send>>) -> io::Result<TapStats> {
        run_signalled(self.opts.signals, "aptscope tap", |sig| {
            self.run_with(display, sig)
        })
    }

    /// [`Tap::run`] with the signals (when handled) already installed by the caller; the
    /// statistics are not printed.
    fn run_with(
        self,
        display: Option<Box<dyn Write + Send>>,
        signals: Option<&Signals>,
    ) -> io::Result<TapStats> {
        let Tap {
            opts,
            settings,
            mut device,
            host,
            rec,
        } = self;
        let Recording { sh, sink, disp_rx } = rec;
        let sh = &*sh;
        let disp = Recording::display(disp_rx, display);
        let deadline = opts.duration.map(|d| Instant::now() + d);
        let mut host_r = host.master.try_clone()?;
        let mut host_w = host.master.try_clone()?;
        let stats = thread::scope(|scope| {
            run_recorded(
                scope,
                sh,
                sink,
                disp,
                (opts.proto, opts.units.clone()),
                || loop {
                    let (mut dev_r, mut dev_w) = match device.take() {
                        Some(d) => d,
                        None => match wait_for_device(
                            &opts.device,
                            &settings,
                            &mut host_r,
                            sh,
                            signals,
                            deadline,
                        ) {
                            Some(d) => d,
                            None => return Ok(()),
                        },
                    };
                    let end = AtomicBool::new(false);
                    let (h2d, d2h) = thread::scope(|s| {
                        let (sh, end) = (&sh, &end);
                        let finish = move |r: FwdEnd| {
                            end.store(true, Ordering::SeqCst);
                            sh.stop.wake();
                            r
                        };
                        let (host_r, host_w) = (&mut host_r, &mut host_w);
                        let (dev_r, dev_w): (&mut dyn Port, &mut dyn Port) =
                            (&mut *dev_r, &mut *dev_w);
                        let h = s.spawn(move || {
                            let to = Some(dev_w);
                            finish(forward(host_r, to, Direction::HostToDevice, sh, end))
                        });
                        let d = s.spawn(move || {
                            let to: Option<&mut dyn Port> = Some(host_w);
                            finish(forward(dev_r, to, Direction::DeviceToHost, sh, end))
                        });
                        supervise(sh, signals, deadline, end);
                        end.store(true, Ordering::SeqCst);
                        (
                            h.join().unwrap_or(FwdEnd::Stopped),
                            d.join().unwrap_or(FwdEnd::Stopped),
                        )
                    });
                    let (dev_gone, host_gone) = match (h2d, d2h) {
                        (FwdEnd::SrcGone(t, e), _) | (_, FwdEnd::DstGone(t, e)) => {
                            (None, Some((t, e)))
                        }
                        (FwdEnd::DstGone(t, e), _) | (_, FwdEnd::SrcGone(t, e)) => {
                            (Some((t, e)), None)
                        }
                        (FwdEnd::Stopped, FwdEnd::Stopped) => (None, None),
                    };
                    if let Some((_, e)) = host_gone {
                        return Err(io::Error::new(e.kind(), format!("host side: {e}")));
                    }
                    if let Some((t, e)) = dev_gone {
                        sh.disconnect(t, &opts.device, &e);
                        if opts.reconnect && !sh.stop.is_stopped() {
                            crate::note!("aptscope tap: waiting for {} to come back", opts.device);
                            continue;
                        }
                    }
                    return Ok(());
                },
            )
        })?;
        drop(host);
        Ok(stats)
    }
}

/// With the device away: keep draining (and discarding) what the host writes, and try to
/// reopen the device every [`RETRY_EVERY`], until it is back or the tap is stopped.
fn wait_for_device(
    path: &str,
    settings: &LineSettings,
    host_r: &mut FdPort,
    sh: &Shared,
    signals: Option<&Signals>,
    deadline: Option<Instant>,
) -> Option<DevicePair> {
    let mut buf = vec![0u8; READ_BUF];
    let mut last_try: Option<Instant> = None;
    loop {
        if sh.stop.is_stopped() {
            return None;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            sh.stop.stop();
            return None;
        }
        if let Some(sig) = signals.and_then(|s| s.wait(Duration::ZERO)) {
            sh.stop.stop();
            crate::note!("aptscope: {sig}: stopping");
            return None;
        }
        if last_try.is_none_or(|t| t.elapsed() >= RETRY_EVERY) {
            last_try = Some(Instant::now());
            if let Ok(d) = open_device(path, settings) {
                crate::note!(
                    "aptscope tap: {path} back at {}",
                    clock_time(sh.clock.now())
                );
                return Some(d);
            }
        }
        match host_r.read_tick(&mut buf) {
            Ok(n) => {
                sh.discarded_h2d.fetch_add(n as u64, Ordering::Relaxed);
            }
            Err(e) => {
                crate::note!("aptscope tap: host side: {e}");
                sh.stop.stop();
                return None;
            }
        }
    }
}

/// Run a sniff: read the two receive-only adapters (each in its own thread), merge both
/// directions by time into the capture, show the timeline, until stopped or an adapter
/// disappears (unless `reconnect`); print and return the statistics.
pub fn sniff_main(opts: SniffOptions) -> io::Result<TapStats> {
    Sniff::new(opts)?.run(None)
}

/// A sniff set up (ports open, file created) and ready to run.
struct Sniff {
    opts: SniffOptions,
    settings: LineSettings,
    ports: Vec<Option<SerialPort>>,
    rec: Recording,
}

impl Sniff {
    fn new(opts: SniffOptions) -> io::Result<Sniff> {
        let settings = LineSettings::for_proto(opts.proto, opts.baud, opts.flow);
        let format = opts
            .write
            .as_deref()
            .map(|p| FileSink::format(p, opts.write_format))
            .transpose()?;
        let mut ports = vec![];
        for p in [&opts.host_tx, &opts.device_tx] {
            ports.push(match open_serial(p, &settings) {
                Ok(port) => Some(port),
                Err(e) if opts.reconnect => {
                    crate::note!("aptscope sniff: {e}; waiting for it");
                    None
                }
                Err(e) => return Err(e),
            });
        }
        let sink = match &opts.write {
            Some(p) => Some(FileSink::for_opts(
                p,
                format.unwrap_or(Format::PcapNg),
                (false, opts.force, opts.followed),
                &StreamInfo {
                    id: 0,
                    name: format!("{} + {}", opts.host_tx, opts.device_tx),
                    settings: Some(format!("{settings} (receive-only Y-cable)")),
                },
            )?),
            None => None,
        };
        crate::note!(
            "aptscope sniff: host TX on {}, device TX on {} ({settings}){}",
            opts.host_tx,
            opts.device_tx,
            opts.write
                .as_ref()
                .map(|w| format!(", writing {w}"))
                .unwrap_or_default()
        );
        let rec = Recording::new(opts.stop.clone(), opts.quiet, sink);
        Ok(Sniff {
            opts,
            settings,
            ports,
            rec,
        })
    }

    /// Run until stopped, with the timeline going to `display` (standard output when `None`).
    fn run(self, display: Option<Box<dyn Write + Send>>) -> io::Result<TapStats> {
        run_signalled(self.opts.signals, "aptscope sniff", |sig| {
            self.run_with(display, sig)
        })
    }

    /// [`Sniff::run`] with the signals already installed by the caller; the statistics are
    /// not printed.
    fn run_with(
        self,
        display: Option<Box<dyn Write + Send>>,
        signals: Option<&Signals>,
    ) -> io::Result<TapStats> {
        let Sniff {
            opts,
            settings,
            ports,
            rec,
        } = self;
        let Recording { sh, sink, disp_rx } = rec;
        let sh = &*sh;
        let disp = Recording::display(disp_rx, display);
        let deadline = opts.duration.map(|d| Instant::now() + d);
        let never = AtomicBool::new(false);
        let stats = thread::scope(|scope| {
            run_recorded(
                scope,
                sh,
                sink,
                disp,
                (opts.proto, opts.units.clone()),
                || {
                    thread::scope(|s| {
                        let dirs = [Direction::HostToDevice, Direction::DeviceToHost];
                        let paths = [&opts.host_tx, &opts.device_tx];
                        for ((port, dir), path) in ports.into_iter().zip(dirs).zip(paths) {
                            let (sh, never, settings) = (&sh, &never, &settings);
                            let reconnect = opts.reconnect;
                            s.spawn(move || {
                                receive(path, port, dir, settings, reconnect, sh, never)
                            });
                        }
                        supervise(sh, signals, deadline, &never);
                        // The receivers see the stop within a tick.
                        sh.stop.stop();
                    });
                    Ok(())
                },
            )
        })?;
        Ok(stats)
    }
}

/// One receive-only adapter of a sniff: read and record until stopped; when it disappears,
/// report it and either stop the sniff or (with `reconnect`) reopen it.
fn receive(
    path: &str,
    mut port: Option<SerialPort>,
    dir: Direction,
    settings: &LineSettings,
    reconnect: bool,
    sh: &Shared,
    never: &AtomicBool,
) {
    loop {
        let mut p = match port.take() {
            Some(p) => p,
            None => loop {
                if sh.stop.is_stopped() {
                    return;
                }
                match open_serial(path, settings) {
                    Ok(p) => {
                        crate::note!(
                            "aptscope sniff: {path} back at {}",
                            clock_time(sh.clock.now())
                        );
                        break p;
                    }
                    Err(_) => {
                        if sh.stop.wait(RETRY_EVERY) {
                            return;
                        }
                    }
                }
            },
        };
        match forward(&mut p, None, dir, sh, never) {
            FwdEnd::Stopped => return,
            FwdEnd::SrcGone(t, e) | FwdEnd::DstGone(t, e) => {
                sh.disconnect(t, path, &e);
                if !reconnect {
                    sh.stop.stop();
                    return;
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// A live view of the file

/// What the live view of a tap, sniff or simulator is given: the capture file being written
/// and the flags that say it is complete and that the view should close.
#[derive(Debug, Clone, Copy)]
pub struct LiveView<'a> {
    /// The capture file (pcapng) the tap writes, flushed as it is written.
    pub path: &'a str,
    /// Where host programs connect (the tap's link, else its pseudo-terminal); `None` for a
    /// sniff.
    pub host: Option<&'a str>,
    /// Set once the file is complete (the tap has ended): a follower reads to its end.
    pub written: FollowStop,
    /// Set when the view should close: the tap was stopped (signal, duration) or failed.
    pub quit: &'a AtomicBool,
}

/// Run a tap writing `opts.write` with `view` in the calling thread (the terminal UI, which
/// follows the file): the recording never waits for the view. When the view returns (the user
/// quit) the tap is stopped; when the tap stops first (signal, duration) the view is asked to
/// close; when the device goes away the view stays on the complete file. Progress lines are
/// held back while the view has the terminal; the statistics are printed after it.
pub fn tap_with_view(
    mut opts: TapOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
) -> io::Result<TapStats> {
    let path = viewed_path(&opts.write)?;
    opts.followed = true;
    opts.quiet = true;
    let tap = Tap::new(opts)?;
    let (signals, stop) = (tap.opts.signals, tap.opts.stop.clone());
    let host = tap.host.link.as_ref().unwrap_or(&tap.host.slave_path);
    let host = format!("host {}", host.display());
    let run = move |sig: Option<&Signals>| tap.run_with(None, sig);
    with_view(
        (&path, Some(&host)),
        (signals, stop),
        "aptscope tap",
        run,
        view,
    )
}

/// [`tap_with_view`] for a sniff.
pub fn sniff_with_view(
    mut opts: SniffOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
) -> io::Result<TapStats> {
    let path = viewed_path(&opts.write)?;
    opts.followed = true;
    opts.quiet = true;
    let sniff = Sniff::new(opts)?;
    let (signals, stop) = (sniff.opts.signals, sniff.opts.stop.clone());
    let run = move |sig: Option<&Signals>| sniff.run_with(None, sig);
    with_view((&path, None), (signals, stop), "aptscope sniff", run, view)
}

/// A simulator's own traffic in a live view: `sim` served on a private pseudo-terminal with a
/// tap in front of it (`opts.device` is set to it) whose host side is what programs open
/// (`opts.link`), recorded to `opts.write` and shown by `view` as [`tap_with_view`] does.
pub fn sim_with_view(
    sim: Box<dyn crate::live::sim::Simulator + Send>,
    mut opts: TapOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
) -> io::Result<TapStats> {
    use crate::live::sim::{serve_pty, stop_pair, Pty};
    use nix::sys::signal::{SigSet, SigmaskHow, Signal};
    // Blocked before the simulator's thread starts, so that it inherits the mask and the
    // signals reach the tap's signalfd rather than killing the process.
    let mut set = SigSet::empty();
    for sig in [Signal::SIGINT, Signal::SIGTERM, Signal::SIGHUP] {
        set.add(sig);
    }
    let old = set.thread_swap_mask(SigmaskHow::SIG_BLOCK)?;
    let pty = Pty::open()?;
    opts.device = pty.path().to_string_lossy().into_owned();
    let (stop, stopped) = stop_pair()?;
    let r = thread::scope(|s| {
        let server = s.spawn(move || {
            let mut sim = sim;
            serve_pty(&mut *sim, pty, Some(&stopped), &[])
        });
        let r = tap_with_view(opts, view);
        stop.stop();
        match server.join() {
            Ok(Err(e)) if r.is_ok() => Err(io::Error::new(e.kind(), format!("simulator: {e}"))),
            Err(_) => Err(io::Error::other("the simulator panicked")),
            _ => r,
        }
    });
    let _ = old.thread_set_mask();
    r
}

/// How long a view asked to close may take before it is given up (see [`abandon_view`]).
const VIEW_GRACE: Duration = Duration::from_secs(2);

/// The view did not close when asked: its terminal has gone (SIGHUP after the terminal
/// closed; the terminal library then never returns from waiting for input). The capture is
/// complete: say so where standard error still goes, and end the process.
fn abandon_view(r: &io::Result<TapStats>, path: &str, what: &str) -> ! {
    crate::set_notes(true);
    let ok = match r {
        Ok(stats) => {
            crate::note!("{}", stats.summary(what));
            stats.file_matches()
        }
        Err(e) => {
            crate::note!("{what}: {e}");
            false
        }
    };
    crate::note!("{what}: capture in {path} (the view's terminal has gone)");
    std::process::exit(if ok { 0 } else { 1 })
}

fn viewed_path(write: &Option<String>) -> io::Result<String> {
    write.clone().ok_or_else(|| {
        io::Error::new(
            io::ErrorKind::InvalidInput,
            "a live view follows the capture file: give one (-w)",
        )
    })
}

/// Run `run` (a tap or sniff, given the signals) in a thread and `view` in this one; see
/// [`tap_with_view`].
fn with_view(
    (path, host): (&str, Option<&str>),
    (signals, stop): (bool, StopHandle),
    what: &str,
    run: impl FnOnce(Option<&Signals>) -> io::Result<TapStats> + Send,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
) -> io::Result<TapStats> {
    // Installed here, before any thread starts: the view's threads inherit the mask too.
    let signals = if signals {
        Some(Signals::install()?)
    } else {
        None
    };
    let written = FollowStop::new();
    let quit = AtomicBool::new(false);
    let view_done = AtomicBool::new(false);
    // The view has the terminal: a line on standard error would scribble over it.
    let notes = crate::notes_on();
    crate::set_notes(false);
    let (stats, shown) = thread::scope(|s| {
        let sig = signals.as_ref();
        let (quit, view_done, tap_stop) = (&quit, &view_done, stop.clone());
        let tap = s.spawn(move || {
            let r = run(sig);
            written.stop();
            if r.is_err() || tap_stop.is_stopped() {
                quit.store(true, Ordering::SeqCst);
            }
            // The view may stay open on the finished file: signals still close it.
            let mut asked: Option<Instant> = None;
            while !view_done.load(Ordering::SeqCst) {
                match sig {
                    Some(sg) => {
                        if sg.wait(TICK).is_some() {
                            quit.store(true, Ordering::SeqCst);
                        }
                    }
                    None => thread::sleep(TICK),
                }
                if quit.load(Ordering::SeqCst) {
                    let t = *asked.get_or_insert_with(Instant::now);
                    if t.elapsed() >= VIEW_GRACE {
                        abandon_view(&r, path, what);
                    }
                }
            }
            r
        });
        let shown = view(LiveView {
            path,
            host,
            written,
            quit,
        });
        view_done.store(true, Ordering::SeqCst);
        stop.stop();
        let stats = tap
            .join()
            .unwrap_or_else(|_| Err(io::Error::other("the tap panicked")));
        (stats, shown)
    });
    crate::set_notes(notes);
    drop(signals);
    let stats = stats?;
    crate::note!("{}", stats.summary(what));
    shown.map(|()| stats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::Event;
    use crate::open::{open, OpenOptions};
    use crate::scratch::scratch;
    use std::os::unix::fs::OpenOptionsExt;
    use std::path::Path;

    /// Generous: only reached when something is broken.
    const DEADLINE: Duration = Duration::from_secs(60);

    /// A pseudo-terminal standing in for a device: the test holds the master, the tap opens
    /// the slave path like a serial port.
    fn fake_device() -> (FdPort, String) {
        let host = HostPty::create(None).unwrap();
        let path = host.slave_path.to_string_lossy().into_owned();
        let master = host.master.try_clone().unwrap();
        // The slave is closed here: the tap's open is then the only one.
        drop(host);
        (master, path)
    }

    /// Open a tty path as the host program would (no controlling terminal).
    fn open_host(path: &Path) -> FdPort {
        let f = File::options()
            .read(true)
            .write(true)
            .custom_flags(OFlag::O_NOCTTY.bits())
            .open(path)
            .unwrap();
        FdPort::new(OwnedFd::from(f)).unwrap()
    }

    fn send(p: &mut FdPort, mut bytes: &[u8]) {
        let t0 = Instant::now();
        while !bytes.is_empty() {
            assert!(t0.elapsed() < DEADLINE, "write timed out");
            let n = p.write_tick(bytes).unwrap();
            bytes = &bytes[n..];
        }
    }

    fn recv(p: &mut FdPort, n: usize) -> Vec<u8> {
        let t0 = Instant::now();
        let mut out = vec![];
        let mut buf = vec![0; 8192];
        while out.len() < n {
            assert!(
                t0.elapsed() < DEADLINE,
                "read timed out after {} of {n} bytes",
                out.len()
            );
            let k = p.read_tick(&mut buf[..(n - out.len()).min(8192)]).unwrap();
            out.extend_from_slice(&buf[..k]);
        }
        out
    }

    /// `n` bytes of back-to-back MOT_MOVE_ABSOLUTE frames (12 bytes each), then a tail.
    fn apt_moves(n: usize) -> Vec<u8> {
        let mut v = Vec::with_capacity(n + 12);
        let mut pos = 0i32;
        while v.len() < n {
            v.extend_from_slice(&[0x53, 0x04, 0x06, 0x00, 0xa2, 0x01, 0x01, 0x00]);
            v.extend_from_slice(&pos.to_le_bytes());
            pos = pos.wrapping_add(977);
        }
        v.truncate(n);
        v
    }

    /// `n` bytes of back-to-back MOT_GET_DCSTATUSUPDATE frames (20 bytes each).
    fn apt_status(n: usize) -> Vec<u8> {
        let mut v = Vec::with_capacity(n + 20);
        let mut pos = 0i32;
        while v.len() < n {
            v.extend_from_slice(&[0x91, 0x04, 0x0e, 0x00, 0x81, 0x50, 0x01, 0x00]);
            v.extend_from_slice(&pos.to_le_bytes());
            v.extend_from_slice(&[0x2c, 0x01, 0x00, 0x00, 0x10, 0x05, 0x00, 0x80]);
            pos = pos.wrapping_sub(313);
        }
        v.truncate(n);
        v
    }

    /// The capture's bytes per direction, its streams, and whether it had diagnostics.
    fn read_back(path: &Path) -> (Vec<u8>, Vec<u8>, Vec<StreamInfo>, Vec<String>) {
        let (mut r, f) = open(path.to_str().unwrap(), OpenOptions::default()).unwrap();
        let want = crate::open::Format::from_extension(path.to_str().unwrap());
        assert_eq!(Some(f), want);
        let (mut h2d, mut d2h, mut streams, mut diags) = (vec![], vec![], vec![], vec![]);
        while let Some(e) = r.next_event() {
            match e {
                Event::Stream(s) => streams.push(s),
                Event::Chunk(c) => {
                    assert!(c.ts_ns.is_some());
                    match c.dir {
                        Direction::HostToDevice => h2d.extend_from_slice(c.bytes),
                        Direction::DeviceToHost => d2h.extend_from_slice(c.bytes),
                        Direction::Unknown => panic!("chunk without direction"),
                    }
                }
                Event::Diag(d) => diags.push(d.to_string()),
            }
        }
        (h2d, d2h, streams, diags)
    }

    fn tap_opts(device: &str, dir: &Path) -> TapOptions {
        let mut o = TapOptions::new(device, Some(dir.join("ttyAPT").to_string_lossy().into()));
        o.write = Some(dir.join("cap.pcapng").to_string_lossy().into());
        o.quiet = true;
        o.signals = false;
        o
    }

    /// Run `f` in a thread, failing (not hanging) when it takes longer than the deadline.
    fn within<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> impl FnOnce() -> T {
        let (tx, rx) = mpsc::channel();
        thread::spawn(move || {
            let _ = tx.send(f());
        });
        move || rx.recv_timeout(DEADLINE).expect("did not finish in time")
    }

    #[derive(Clone, Default)]
    struct Shown(Arc<Mutex<Vec<u8>>>);
    impl Write for Shown {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            lock(&self.0).extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn forwards_both_ways_losslessly_and_records_exactly_what_crossed() {
        let dir = scratch("both");
        let (mut dev, dev_path) = fake_device();
        let mut opts = tap_opts(&dev_path, &dir);
        opts.quiet = false;
        let stop = opts.stop.clone();
        let tap = Tap::new(opts).unwrap();
        let shown = Shown::default();
        let out = shown.clone();
        let done = within(move || tap.run(Some(Box::new(out))));
        let link = dir.join("ttyAPT");
        assert!(std::fs::read_link(&link).is_ok());
        let mut host = open_host(&link);

        // A request and its reply.
        let req = [0x05, 0x00, 0x00, 0x00, 0x50, 0x01]; // HW_REQ_INFO
        send(&mut host, &req);
        assert_eq!(recv(&mut dev, req.len()), req);
        let mut reply = vec![0x06, 0x00, 0x54, 0x00, 0x81, 0x50];
        reply.extend((0..84u8).map(|i| i.wrapping_mul(7)));
        send(&mut dev, &reply);
        assert_eq!(recv(&mut host, reply.len()), reply);

        // 1 MB of back-to-back frames each way at once.
        const MB: usize = 1 << 20;
        let (moves, status) = (apt_moves(MB), apt_status(MB));
        let mut host_rx = host.try_clone().unwrap();
        let mut dev_rx = dev.try_clone().unwrap();
        // (The threads hand their ports back: closing the device's master would hang it up.)
        let got_d2h = thread::spawn(move || (recv(&mut host_rx, MB), host_rx));
        let got_h2d = thread::spawn(move || (recv(&mut dev_rx, MB), dev_rx));
        let m = moves.clone();
        let w1 = thread::spawn(move || {
            send(&mut host, &m);
            host
        });
        let st = status.clone();
        let w2 = thread::spawn(move || {
            send(&mut dev, &st);
            dev
        });
        let _host = w1.join().unwrap();
        let _dev = w2.join().unwrap();
        let (got, _dev_rx) = got_h2d.join().unwrap();
        assert!(got == moves, "device got other bytes");
        let (got, _host_rx) = got_d2h.join().unwrap();
        assert!(got == status, "host got other bytes");

        stop.stop();
        let stats = done().unwrap();
        let sent_h2d = [&req[..], &moves].concat();
        let sent_d2h = [&reply[..], &status].concat();
        assert_eq!(stats.bytes_h2d, sent_h2d.len() as u64);
        assert_eq!(stats.bytes_d2h, sent_d2h.len() as u64);
        assert!(stats.file_matches(), "{}", stats.summary("test"));
        assert!(stats.disconnects.is_empty());
        assert_eq!(stats.undelivered, 0);

        let (h2d, d2h, streams, diags) = read_back(&dir.join("cap.pcapng"));
        assert!(diags.is_empty(), "{diags:?}");
        assert!(h2d == sent_h2d, "file h2d differs");
        assert!(d2h == sent_d2h, "file d2h differs");
        assert_eq!(streams.len(), 1);
        assert_eq!(streams[0].name, dev_path);
        assert_eq!(streams[0].settings.as_deref(), Some("115200 8N1 RTS/CTS"));

        let shown = String::from_utf8_lossy(&lock(&shown.0)).into_owned();
        let first = shown.lines().next().unwrap_or_default();
        assert!(first.contains("HW_REQ_INFO"), "{first}");
        assert!(shown.contains("MOT_MOVE_ABSOLUTE"));
        // The link goes with the tap.
        assert!(std::fs::symlink_metadata(&link).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn device_gone_mid_stream_is_reported_and_the_file_stays_valid() {
        let dir = scratch("gone");
        let (mut dev, dev_path) = fake_device();
        let tap = Tap::new(tap_opts(&dev_path, &dir)).unwrap();
        let done = within(move || tap.run(None));
        let mut host = open_host(&dir.join("ttyAPT"));
        let a = apt_moves(600);
        send(&mut host, &a);
        assert_eq!(recv(&mut dev, a.len()), a);
        let b = apt_status(400);
        send(&mut dev, &b);
        assert_eq!(recv(&mut host, b.len()), b);
        let before = Instant::now();
        drop(dev); // the cable is pulled
        let stats = done().unwrap();
        assert_eq!(stats.disconnects.len(), 1, "{}", stats.summary("test"));
        let d = &stats.disconnects[0];
        assert_eq!(d.port, dev_path);
        assert!(d.ts_ns > 0 && !d.error.is_empty());
        assert!(before.elapsed() < Duration::from_secs(10));
        assert!(stats.file_matches(), "{}", stats.summary("test"));
        let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcapng"));
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!((h2d, d2h), (a, b));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn reconnect_waits_for_the_device_and_carries_on_in_the_same_file() {
        let dir = scratch("reconnect");
        let dev_link = dir.join("ttyUSB0");
        let (mut dev, p1) = fake_device();
        std::os::unix::fs::symlink(&p1, &dev_link).unwrap();
        let mut opts = tap_opts(dev_link.to_str().unwrap(), &dir);
        opts.reconnect = true;
        let stop = opts.stop.clone();
        let tap = Tap::new(opts).unwrap();
        let done = within(move || tap.run(None));
        let mut host = open_host(&dir.join("ttyAPT"));
        let a = apt_moves(120);
        send(&mut host, &a);
        assert_eq!(recv(&mut dev, a.len()), a);
        drop(dev);

        // The device comes back under the same name.
        let (mut dev2, p2) = fake_device();
        std::fs::remove_file(&dev_link).unwrap();
        std::os::unix::fs::symlink(&p2, &dev_link).unwrap();
        // Written before the tap reopens it: waits in the pty until then.
        let b = apt_status(200);
        send(&mut dev2, &b);
        assert_eq!(recv(&mut host, b.len()), b);
        let c = apt_moves(240);
        send(&mut host, &c);
        assert_eq!(recv(&mut dev2, c.len()), c);

        stop.stop();
        let stats = done().unwrap();
        assert_eq!(stats.disconnects.len(), 1);
        assert!(stats.file_matches(), "{}", stats.summary("test"));
        let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcapng"));
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!(h2d, [a, c].concat());
        assert_eq!(d2h, b);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn sniff_merges_two_receive_only_ports() {
        let dir = scratch("sniff");
        let (mut htx, hp) = fake_device();
        let (mut dtx, dp) = fake_device();
        let mut opts = SniffOptions::new(&hp, &dp);
        opts.write = Some(dir.join("sniff.pcapng").to_string_lossy().into());
        opts.quiet = true;
        opts.signals = false;
        let stop = opts.stop.clone();
        let sniff = Sniff::new(opts).unwrap();
        let sh = sniff.rec.sh.clone();
        let done = within(move || sniff.run(None));
        let (mut h, mut d) = (vec![], vec![]);
        for i in 0..20 {
            let q = apt_moves(12 * (i + 1));
            let r = apt_status(20 * (i + 1));
            send(&mut htx, &q);
            send(&mut dtx, &r);
            h.extend(q);
            d.extend(r);
        }
        let big = apt_status(256 << 10);
        send(&mut dtx, &big);
        d.extend(big);
        // Stop once the sniff has read everything (its counters say when).
        let t0 = Instant::now();
        while sh.fwd[0].load(Ordering::SeqCst) < h.len() as u64
            || sh.fwd[1].load(Ordering::SeqCst) < d.len() as u64
        {
            assert!(t0.elapsed() < DEADLINE, "the sniff did not read everything");
            thread::park_timeout(Duration::from_millis(5));
        }
        stop.stop();
        let stats = done().unwrap();
        assert!(stats.file_matches(), "{}", stats.summary("test"));
        assert_eq!(
            (stats.bytes_h2d, stats.bytes_d2h),
            (h.len() as u64, d.len() as u64)
        );
        let (fh, fd, streams, diags) = read_back(&dir.join("sniff.pcapng"));
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!(streams[0].name, format!("{hp} + {dp}"));
        assert!(fh == h && fd == d, "file differs");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_file_is_readable_while_the_tap_runs() {
        // What a `kill -9` would leave: the file as flushed so far, never finished.
        let dir = scratch("live-file");
        let (mut dev, dev_path) = fake_device();
        let opts = tap_opts(&dev_path, &dir);
        let stop = opts.stop.clone();
        let tap = Tap::new(opts).unwrap();
        let done = within(move || tap.run(None));
        let mut host = open_host(&dir.join("ttyAPT"));
        let a = apt_moves(1200);
        send(&mut host, &a);
        assert_eq!(recv(&mut dev, a.len()), a);
        let t0 = Instant::now();
        loop {
            let (h2d, _, _, diags) = read_back(&dir.join("cap.pcapng"));
            assert!(diags.is_empty(), "{diags:?}");
            if h2d == a {
                break;
            }
            assert!(t0.elapsed() < DEADLINE, "not flushed");
            thread::park_timeout(Duration::from_millis(20));
        }
        stop.stop();
        assert!(done().unwrap().file_matches());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_existing_file_is_kept_without_force() {
        let dir = scratch("exists");
        let (_dev, dev_path) = fake_device();
        let opts = tap_opts(&dev_path, &dir);
        std::fs::write(opts.write.as_ref().unwrap(), b"precious").unwrap();
        let e = Tap::new(opts.clone()).err().unwrap();
        assert_eq!(e.kind(), io::ErrorKind::AlreadyExists);
        assert_eq!(
            std::fs::read(opts.write.as_ref().unwrap()).unwrap(),
            b"precious"
        );
        // A missing device is an error at once without `reconnect`.
        let mut o = tap_opts(dir.join("nope").to_str().unwrap(), &dir);
        o.force = true;
        assert!(Tap::new(o).is_err());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_stream_goes_into_an_existing_pipe_and_ends_with_its_reader() {
        let dir = scratch("stream");
        let (mut dev, dev_path) = fake_device();
        let fifo = dir.join("fifo");
        // Never created, nor written over when it is a file.
        let mut o = tap_opts(&dev_path, &dir);
        o.stream = true;
        o.write = Some(fifo.to_string_lossy().into());
        assert_eq!(
            Tap::new(o.clone()).err().unwrap().kind(),
            io::ErrorKind::NotFound
        );
        assert!(!fifo.exists());
        std::fs::write(&fifo, b"precious").unwrap();
        let e = Tap::new(o.clone()).err().unwrap();
        assert!(e.to_string().contains("not a pipe"), "{e}");
        assert_eq!(std::fs::read(&fifo).unwrap(), b"precious");
        std::fs::remove_file(&fifo).unwrap();

        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let mut r = File::options()
            .read(true)
            .custom_flags(OFlag::O_NONBLOCK.bits())
            .open(&fifo)
            .unwrap();
        let tap = Tap::new(o).unwrap();
        let done = within(move || tap.run(None));
        let mut host = open_host(&dir.join("ttyAPT"));
        let a = apt_moves(48);
        send(&mut host, &a);
        assert_eq!(recv(&mut dev, a.len()), a);
        let mut got = vec![];
        let t0 = Instant::now();
        while !got.windows(a.len()).any(|w| w == a) {
            assert!(t0.elapsed() < DEADLINE, "never flushed");
            let mut buf = [0u8; 4096];
            match r.read(&mut buf) {
                Ok(n) => got.extend_from_slice(&buf[..n]),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    thread::park_timeout(Duration::from_millis(5))
                }
                Err(e) => panic!("{e}"),
            }
        }
        // The reader goes: the tap ends by itself, saying why.
        drop(r);
        let stats = done().unwrap();
        assert!(stats.reader_closed, "{}", stats.summary("test"));
        assert!(stats.summary("test").contains("its reader closed it"));
        let cap = dir.join("got.pcapng");
        std::fs::write(&cap, &got).unwrap();
        let (h2d, _, _, diags) = read_back(&cap);
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!(h2d, a);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn writes_pcap_by_extension_and_refuses_non_streaming_formats() {
        let dir = scratch("pcap");
        let (mut dev, dev_path) = fake_device();
        let mut opts = tap_opts(&dev_path, &dir);
        opts.write = Some(dir.join("cap.pcap").to_string_lossy().into());
        let stop = opts.stop.clone();
        let tap = Tap::new(opts).unwrap();
        let done = within(move || tap.run(None));
        let mut host = open_host(&dir.join("ttyAPT"));
        let a = apt_moves(48);
        send(&mut host, &a);
        assert_eq!(recv(&mut dev, a.len()), a);
        let b = apt_status(40);
        send(&mut dev, &b);
        assert_eq!(recv(&mut host, b.len()), b);
        stop.stop();
        assert!(done().unwrap().file_matches());
        let (h2d, d2h, _, diags) = read_back(&dir.join("cap.pcap"));
        assert!(diags.is_empty(), "{diags:?}");
        assert_eq!((h2d, d2h), (a, b));

        let mut o = tap_opts(&dev_path, &dir);
        o.write = Some(dir.join("cap.mcap").to_string_lossy().into());
        let e = Tap::new(o).err().unwrap();
        assert!(e.to_string().contains("pcapng or pcap"), "{e}");
        assert!(!dir.join("cap.mcap").exists(), "nothing created");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn merger_orders_by_time_and_keeps_each_direction_in_order() {
        let rec = |ts, dir, b: u8| {
            Arc::new(Rec {
                ts,
                dir,
                bytes: vec![b],
            })
        };
        let mut m = Merger::default();
        m.push(rec(10, Direction::HostToDevice, 1));
        m.push(rec(30, Direction::HostToDevice, 2));
        m.push(rec(20, Direction::DeviceToHost, 3));
        // 10 < 20: written; then 20 < 30; then 30 waits for the horizon.
        let got: Vec<u8> = std::iter::from_fn(|| m.pop(Some(25)))
            .map(|r| r.bytes[0])
            .collect();
        assert_eq!(got, [1, 3]);
        assert!(m.pop(Some(29)).is_none());
        assert_eq!(m.pop(None).unwrap().bytes, [2]);
    }

    #[test]
    fn the_file_queue_applies_backpressure_instead_of_dropping() {
        let q = Arc::new(FileQueue::new(10));
        let rec = |n| {
            QItem::Chunk(Arc::new(Rec {
                ts: 0,
                dir: Direction::HostToDevice,
                bytes: vec![0; n],
            }))
        };
        q.push(rec(8));
        let q2 = q.clone();
        let pusher = thread::spawn(move || q2.push(rec(8)));
        let t0 = Instant::now();
        while q.waits.load(Ordering::SeqCst) == 0 {
            assert!(t0.elapsed() < DEADLINE);
            thread::park_timeout(Duration::from_millis(5));
        }
        assert_eq!(q.pop_all(TICK).0.len(), 1);
        pusher.join().unwrap();
        assert_eq!(q.pop_all(TICK).0.len(), 1);
        assert_eq!(q.lost.load(Ordering::SeqCst), 0);
        // Once writing failed, nothing waits and the loss is counted.
        q.fail();
        q.push(rec(30));
        assert_eq!(q.lost.load(Ordering::SeqCst), 30);
    }

    #[test]
    fn line_settings_follow_the_protocol() {
        let apt = LineSettings::for_proto(Proto::Apt, None, None);
        assert_eq!(apt.to_string(), "115200 8N1 RTS/CTS");
        let ell = LineSettings::for_proto(Proto::Elliptec, None, None);
        assert_eq!(ell.to_string(), "9600 8N1");
        let o = LineSettings::for_proto(Proto::Apt, Some(9600), Flow::parse("none"));
        assert_eq!(o.to_string(), "9600 8N1");
        assert_eq!(clock_time(3_723_004_000_000), "01:02:03.004 UTC");
    }
}
