//! What the threads of a tap or sniff share, the forwarding loop, the supervisor that watches
//! for a stop, and the frame that runs the file writer and the display beside a run.

use super::display::{display_loop, LineOut};
use super::port::Port;
use super::queue::{FileQueue, QItem, Rec};
use super::sink::FileSink;
use super::writer::{writer_loop, WriterOut};
use super::{clock_time, Clock, Disconnect, StopHandle, TapStats, DISPLAY_QUEUE, FILE_BACKLOG};
use super::{READ_BUF, TICK};
use crate::live::error::LiveError;
use crate::live::signals::{Signals, STOP};
use crate::live::stop::lock;
use crate::model::Direction;
use crate::Say;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::units::UnitsOpts;
use std::io::{self, Write};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::Instant;

/// What all threads share.
pub(super) struct Shared {
    pub(super) clock: Clock,
    pub(super) stop: StopHandle,
    /// Where the run's progress lines go.
    pub(super) say: Say,
    /// Bytes that crossed, per direction (host → device first); also read by the tests.
    pub(super) fwd: Arc<[AtomicU64; 2]>,
    pub(super) chunks: AtomicU64,
    pub(super) undelivered: AtomicU64,
    pub(super) discarded_h2d: AtomicU64,
    pub(super) file: Option<FileQueue>,
    pub(super) display: Option<SyncSender<Arc<Rec>>>,
    pub(super) display_skipped: AtomicU64,
    pub(super) display_done: AtomicBool,
    pub(super) disconnects: Mutex<Vec<Disconnect>>,
}

impl Shared {
    pub(super) fn new(
        stop: StopHandle,
        say: Say,
        fwd: Arc<[AtomicU64; 2]>,
        file: bool,
        display: Option<SyncSender<Arc<Rec>>>,
    ) -> Shared {
        Shared {
            clock: Clock::new(),
            stop,
            say,
            fwd,
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
    pub(super) fn show(&self, rec: &Arc<Rec>) {
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
    pub(super) fn record(&self, rec: Arc<Rec>) {
        let i = usize::from(rec.dir == Direction::DeviceToHost);
        self.fwd[i].fetch_add(rec.bytes.len() as u64, Ordering::Relaxed);
        self.chunks.fetch_add(1, Ordering::Relaxed);
        if let Some(q) = &self.file {
            q.push(QItem::Chunk(rec));
        }
    }

    pub(super) fn disconnect(&self, ts_ns: u64, port: &str, error: &io::Error) {
        let d = Disconnect {
            ts_ns,
            port: port.to_string(),
            error: error.to_string(),
        };
        self.say.line(format_args!(
            "aptscope: {} gone at {} (+{:.3} s): {}",
            d.port,
            clock_time(ts_ns),
            ts_ns.saturating_sub(self.clock.base_ns) as f64 / 1e9,
            d.error
        ));
        lock(&self.disconnects).push(d);
        if let Some(q) = &self.file {
            q.push(QItem::Sync);
        }
    }

    pub(super) fn stats(&self, w: Option<WriterOut>) -> TapStats {
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

pub(super) enum FwdEnd {
    /// Asked to stop (or the session ended on the other direction).
    Stopped,
    /// The read side failed.
    SrcGone(u64, io::Error),
    /// The write side failed.
    DstGone(u64, io::Error),
}

/// Read `src`, write each chunk whole to `dst` (when there is one: a sniff has none), record
/// what was delivered. Returns when stopped, when `end` is set, or when a side fails.
pub(super) fn forward(
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
pub(super) fn supervise(
    sh: &Shared,
    signals: Option<&Signals>,
    deadline: Option<Instant>,
    end: &AtomicBool,
) {
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
                    sh.say.line(format_args!("aptscope: {sig}: stopping"));
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
pub(super) fn run_recorded<'s, 'e: 's>(
    scope: &'s thread::Scope<'s, 'e>,
    sh: &'e Shared,
    sink: Option<FileSink>,
    display: Option<DisplayTo>,
    decode: (Proto, UnitsOpts),
    body: impl FnOnce() -> Result<(), LiveError>,
) -> Result<TapStats, LiveError> {
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
pub(super) type DisplayTo = (Receiver<Arc<Rec>>, Box<dyn Write + Send>);

/// What a tap or sniff records into: the shared state, the file, the display's channel.
pub(super) struct Recording {
    stop: StopHandle,
    quiet: bool,
    sink: Option<FileSink>,
    fwd: Arc<[AtomicU64; 2]>,
}

impl Recording {
    pub(super) fn new(stop: StopHandle, quiet: bool, sink: Option<FileSink>) -> Recording {
        Recording {
            stop,
            quiet,
            sink,
            fwd: Arc::new([AtomicU64::new(0), AtomicU64::new(0)]),
        }
    }

    /// The bytes that will have crossed, per direction, as the run counts them.
    #[cfg(test)]
    pub(super) fn forwarded(&self) -> Arc<[AtomicU64; 2]> {
        self.fwd.clone()
    }

    /// Start recording, saying progress with `say`: the shared state, the file, and the
    /// display's channel and where it writes (standard output unless `out`).
    pub(super) fn start(
        self,
        say: Say,
        out: Option<Box<dyn Write + Send>>,
    ) -> (Shared, Option<FileSink>, Option<DisplayTo>) {
        let (tx, rx) = if self.quiet {
            (None, None)
        } else {
            let (tx, rx) = mpsc::sync_channel(DISPLAY_QUEUE);
            (Some(tx), Some(rx))
        };
        let sh = Shared::new(self.stop, say, self.fwd, self.sink.is_some(), tx);
        (sh, self.sink, Recording::display(rx, out))
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

/// A tap or a sniff, set up and ready to run.
pub(super) trait Run: Sized + Send {
    /// What says its statistics: `aptscope tap`, `aptscope sniff`.
    const WHAT: &'static str;

    /// Whether it handles the stop signals, its stop handle, and where it says progress.
    fn control(&self) -> (bool, StopHandle, Say);

    /// Run until stopped, with the timeline going to `display` (standard output when `None`)
    /// and the signals (when handled) installed by the caller; progress goes to `say`, the
    /// statistics are returned, not said.
    fn run_with(
        self,
        display: Option<Box<dyn Write + Send>>,
        signals: Option<&Signals>,
        say: Say,
    ) -> Result<TapStats, LiveError>;

    /// [`Run::run_installed`] with the signals installed now, after the set-up (the tests
    /// run a tap set up by hand this way).
    #[cfg(test)]
    fn run(self, display: Option<Box<dyn Write + Send>>) -> Result<TapStats, LiveError> {
        let signals = stop_signals(self.control().0)?;
        self.run_installed(display, signals)
    }

    /// [`Run::run_with`] with the stop signals already installed by the caller (before the
    /// set-up made what a stop is sent for: the host link), then the statistics said.
    fn run_installed(
        self,
        display: Option<Box<dyn Write + Send>>,
        signals: Option<Signals>,
    ) -> Result<TapStats, LiveError> {
        let say = self.control().2;
        let stats = self.run_with(display, signals.as_ref(), say)?;
        drop(signals);
        say.line(format_args!("{}", stats.summary(Self::WHAT)));
        Ok(stats)
    }
}

/// The stop signals received through a signalfd from now on (when `handle`), in this thread
/// and the threads it starts afterwards.
pub(super) fn stop_signals(handle: bool) -> Result<Option<Signals>, LiveError> {
    Ok(if handle {
        Some(Signals::install(STOP)?)
    } else {
        None
    })
}
