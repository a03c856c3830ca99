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
//! - **Stopping**: SIGINT, SIGTERM and SIGHUP are received through a `signalfd` (the signals
//!   are blocked in the tap's threads while it runs and the previous mask restored after, see
//!   [`crate::live::signals`]), or [`StopHandle::stop`], or the end of
//!   [`LiveOptions::duration`]. The file is then
//!   finished, and the byte counts per direction are printed and checked against what was
//!   forwarded.
//! - **Device gone** (read/write error or end of file on the port): reported with the time, the
//!   file is flushed (complete and valid at that point); without `reconnect` the tap ends, with
//!   it the tap waits for the device path to come back and carries on in the same file. While
//!   the device is away, what the host writes is read and discarded (not queued up to reach the
//!   device late) and counted in [`TapStats::discarded_h2d`].
//!
//! # Files
//!
//! One per job: `port.rs` (the ports and the host's pseudo-terminal), `queue.rs` (the file's
//! queue), `sink.rs` (the capture file), `writer.rs` (merging by time, writing, flushing),
//! `display.rs` (the live timeline), `record.rs` (what the threads share, forwarding, the
//! supervisor), `mitm.rs` (the tap proper), `sniff.rs`, `view.rs` (a live view of the file),
//! `stats.rs` (what a run did). The stop handle, the signals and the pseudo-terminal are
//! shared with the simulators' runner ([`crate::live::stop`], [`crate::live::signals`],
//! [`crate::live::pty`]).

mod display;
mod mitm;
mod port;
mod queue;
mod record;
mod sink;
mod sniff;
mod stats;
mod view;
mod writer;

pub use crate::live::stop::StopHandle;
pub use mitm::tap_main;
pub use sniff::sniff_main;
pub use stats::{Disconnect, TapStats};
pub use view::{sim_with_view, sniff_with_view, tap_with_view, LiveView, ViewAbandoned};

use crate::live::serial::Flow;
use crate::open::Format;
use crate::Say;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::units::UnitsOpts;
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

/// What a tap and a sniff share: the line, the capture file, when to stop and what to say.
#[derive(Debug, Clone)]
pub struct LiveOptions {
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
    /// When the device (an adapter) disappears, wait for it to come back instead of ending.
    pub reconnect: bool,
    /// No live timeline on standard output.
    pub quiet: bool,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Stop on SIGINT/SIGTERM/SIGHUP (Linux; blocks them in the calling thread while running).
    pub signals: bool,
    /// Stops the run from another thread.
    pub stop: StopHandle,
    /// Where progress lines (the device gone, the statistics …) are said.
    pub say: Say,
    /// Stage or scale for the live timeline's APT motion values (physical units beside raw).
    pub units: UnitsOpts,
    /// A live view follows the `write` file: it is flushed whenever something was written
    /// (every [`TICK`] at most) instead of every 200 ms (set by [`tap_with_view`]).
    pub followed: bool,
}

impl Default for LiveOptions {
    /// APT with the protocol's line settings, no file, signals handled, progress on stderr.
    fn default() -> Self {
        LiveOptions {
            proto: Proto::Apt,
            baud: None,
            flow: None,
            write: None,
            write_format: None,
            force: false,
            reconnect: false,
            quiet: false,
            duration: None,
            signals: true,
            stop: StopHandle::new(),
            say: Say::Stderr,
            units: UnitsOpts::default(),
            followed: false,
        }
    }
}

/// Options of [`tap_main`].
#[derive(Debug, Clone)]
pub struct TapOptions {
    /// The real serial port (`/dev/ttyUSB0`).
    pub device: String,
    /// Where to symlink the pseudo-terminal the host program opens instead (`/tmp/ttyAPT`);
    /// an existing symlink there is replaced, anything else is refused.
    pub link: Option<String>,
    /// `write` is a pipe that already exists (the FIFO Wireshark gives an extcap): it is opened
    /// as it is (never created or truncated), pcapng unless `write_format` says, flushed as soon
    /// as packets are written (a live reader shows them at once), and the tap stops when the
    /// reader closes it ([`TapStats::reader_closed`]).
    pub stream: bool,
    /// What a tap shares with a sniff.
    pub live: LiveOptions,
}

impl TapOptions {
    /// APT defaults for `device`, symlinked at `link`, no file, signals handled.
    pub fn new(device: impl Into<String>, link: Option<String>) -> Self {
        TapOptions {
            device: device.into(),
            link,
            stream: false,
            live: LiveOptions::default(),
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
    /// What a sniff shares with a tap.
    pub live: LiveOptions,
}

impl SniffOptions {
    /// APT defaults (baud 115200, no flow control: receive-only adapters see no handshake) for
    /// the two adapters.
    pub fn new(host_tx: impl Into<String>, device_tx: impl Into<String>) -> Self {
        SniffOptions {
            host_tx: host_tx.into(),
            device_tx: device_tx.into(),
            live: LiveOptions {
                flow: Some(Flow::None),
                ..LiveOptions::default()
            },
        }
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

#[cfg(test)]
mod tests;
