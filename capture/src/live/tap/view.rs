//! A live view of the capture file: a tap, sniff or simulator recording in one thread while a
//! view (the terminal UI) follows the file in the calling one.

use super::mitm::Tap;
use super::record::{stop_signals, Run};
use super::sniff::Sniff;
use super::{SniffOptions, StopHandle, TapOptions, TapStats, TICK};
use crate::follow::FollowStop;
use crate::live::error::LiveError;
use crate::live::pty::Pty;
use crate::live::signals::{Blocked, Signals, STOP};
use crate::Say;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

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

/// The view did not close when asked: its terminal has gone (SIGHUP after the terminal closed;
/// the terminal library then never returns from waiting for input, so the run cannot return
/// either). The capture is complete and the statistics have been said; what is left is to end
/// the process, which is the caller's to do (the `abandon` argument of [`tap_with_view`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ViewAbandoned {
    /// Whether the capture holds everything that was forwarded.
    pub capture_ok: bool,
}

impl ViewAbandoned {
    /// The process's exit status: 0 when the capture is good, else 1.
    pub fn exit_code(self) -> i32 {
        if self.capture_ok {
            0
        } else {
            1
        }
    }
}

/// Run a tap writing `opts.live.write` with `view` in the calling thread (the terminal UI, which
/// follows the file): the recording never waits for the view. When the view returns (the user
/// quit) the tap is stopped; when the tap stops first (signal, duration) the view is asked to
/// close; when the device goes away the view stays on the complete file. Progress lines are
/// held back while the view has the terminal; the statistics are said after it (to
/// `opts.live.say`). A view that does not close when asked is given up: `abandon` is called (from
/// another thread) and must end the process.
pub fn tap_with_view(
    mut opts: TapOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
    abandon: fn(ViewAbandoned) -> !,
) -> Result<TapStats, LiveError> {
    let path = viewed_path(&opts.live.write)?;
    opts.live.followed = true;
    opts.live.quiet = true;
    // Handled before the set-up, as `tap_main` does, and before any thread starts: the view's
    // threads inherit the mask too.
    let signals = stop_signals(opts.live.signals)?;
    let tap = Tap::new(opts)?;
    let host = format!("host {}", tap.host.path().display());
    view_run(tap, signals, (&path, Some(&host)), view, abandon)
}

/// [`tap_with_view`] for a sniff.
pub fn sniff_with_view(
    mut opts: SniffOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
    abandon: fn(ViewAbandoned) -> !,
) -> Result<TapStats, LiveError> {
    let path = viewed_path(&opts.live.write)?;
    opts.live.followed = true;
    opts.live.quiet = true;
    let signals = stop_signals(opts.live.signals)?;
    let sniff = Sniff::new(opts)?;
    view_run(sniff, signals, (&path, None), view, abandon)
}

/// Run `run` (a tap or sniff set up to write `path`; host programs connect at `host`; the stop
/// `signals` installed before its set-up) in a thread and `view` in this one; see
/// [`tap_with_view`].
fn view_run<R: Run>(
    run: R,
    signals: Option<Signals>,
    (path, host): (&str, Option<&str>),
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
    abandon: fn(ViewAbandoned) -> !,
) -> Result<TapStats, LiveError> {
    let (_, stop, say) = run.control();
    let viewed = Viewed {
        path,
        host,
        stop,
        say,
        what: R::WHAT,
        abandon,
    };
    // The view has the terminal: the run says nothing while it does.
    viewed.run(
        signals,
        move |sig| run.run_with(None, sig, Say::Nothing),
        view,
    )
}

/// A simulator's own traffic in a live view: `sim` served on a private pseudo-terminal with a
/// tap in front of it (`opts.device` is set to it) whose host side is what programs open
/// (`opts.link`), recorded to `opts.live.write` and shown by `view` as [`tap_with_view`] does.
pub fn sim_with_view(
    sim: Box<dyn crate::live::sim::Simulator + Send>,
    mut opts: TapOptions,
    view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
    abandon: fn(ViewAbandoned) -> !,
) -> Result<TapStats, LiveError> {
    use crate::live::sim::serve_pty;
    // Blocked before the simulator's thread starts, so that it inherits the mask and the
    // signals reach the tap's signalfd rather than killing the process.
    let blocked = Blocked::new(STOP)?;
    let pty = Pty::open()?;
    opts.device = pty.path().to_string_lossy().into_owned();
    let stop = StopHandle::new();
    let stopped = stop.clone();
    let r = thread::scope(|s| {
        let server = s.spawn(move || {
            let mut sim = sim;
            serve_pty(&mut *sim, pty, Some(&stopped), &[])
        });
        let r = tap_with_view(opts, view, abandon);
        stop.stop();
        match server.join() {
            Ok(Err(e)) if r.is_ok() => Err(LiveError::Simulator(e)),
            Err(_) => Err(LiveError::Panicked("simulator")),
            _ => r,
        }
    });
    drop(blocked);
    r
}

/// How long a view asked to close may take before it is given up (see [`ViewAbandoned`]).
const VIEW_GRACE: Duration = Duration::from_secs(2);

fn viewed_path(write: &Option<String>) -> Result<String, LiveError> {
    write.clone().ok_or(LiveError::NoViewFile)
}

/// A tap or sniff set up for a live view, and how to end it.
struct Viewed<'a> {
    /// The capture file.
    path: &'a str,
    /// Where host programs connect (a tap's).
    host: Option<&'a str>,
    /// The run's stop handle.
    stop: StopHandle,
    /// Where the statistics are said after the view.
    say: Say,
    /// `aptscope tap`, `aptscope sniff`: what says them.
    what: &'a str,
    /// Ends the process when the view does not close (see [`ViewAbandoned`]).
    abandon: fn(ViewAbandoned) -> !,
}

impl Viewed<'_> {
    /// Run `run` (a tap or sniff, given the `signals` its caller installed) in a thread and
    /// `view` in this one; see [`tap_with_view`].
    fn run(
        self,
        signals: Option<Signals>,
        run: impl FnOnce(Option<&Signals>) -> Result<TapStats, LiveError> + Send,
        view: impl FnOnce(LiveView<'_>) -> io::Result<()>,
    ) -> Result<TapStats, LiveError> {
        let written = FollowStop::new();
        let quit = AtomicBool::new(false);
        let view_done = AtomicBool::new(false);
        let (stats, shown) = thread::scope(|s| {
            let sig = signals.as_ref();
            let (quit, view_done, tap_stop) = (&quit, &view_done, self.stop.clone());
            let this = &self;
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
                            this.abandon_view(&r);
                        }
                    }
                }
                r
            });
            let shown = view(LiveView {
                path: self.path,
                host: self.host,
                written,
                quit,
            });
            view_done.store(true, Ordering::SeqCst);
            self.stop.stop();
            let stats = tap.join().unwrap_or(Err(LiveError::Panicked("tap")));
            (stats, shown)
        });
        drop(signals);
        let stats = stats?;
        self.say.line(format_args!("{}", stats.summary(self.what)));
        Ok(shown.map(|()| stats)?)
    }

    /// The view did not close when asked: say what the run did and where the capture is
    /// (standard error may still go somewhere), and hand the verdict to `abandon`.
    fn abandon_view(&self, r: &Result<TapStats, LiveError>) -> ! {
        let (say, what) = (self.say, self.what);
        let capture_ok = match r {
            Ok(stats) => {
                say.line(format_args!("{}", stats.summary(what)));
                stats.file_matches()
            }
            Err(e) => {
                say.line(format_args!("{what}: {e}"));
                false
            }
        };
        say.line(format_args!(
            "{what}: capture in {} (the view's terminal has gone)",
            self.path
        ));
        (self.abandon)(ViewAbandoned { capture_ok })
    }
}
