//! aptscope-tui: the terminal UI of `aptscope view FILE`.
//!
//! Architecture (state → events → view): [`index`] builds a compact index of the capture in a
//! background thread from the one decode chain's records; [`scan`] runs the display filter and
//! statistics over it in another, reading the compact records through [`fields::View`];
//! [`app::App`] holds the UI state and handles keys and mouse events without a terminal;
//! [`ui::draw`] renders the state, decoding only the visible rows ([`decode`]);
//! [`as_filter`] turns a detail line into a display filter.
//!
//! Files open with [`run_with`]; live sources (a tap, a simulator, a file still being written)
//! with [`run_source`] and `live: true`: the index grows while the view is open, the timeline
//! follows it (LIVE / PAUSED in the status bar) and filters and statistics extend as records
//! arrive.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod app;
pub mod as_filter;
pub mod decode;
pub mod fields;
pub mod index;
pub mod scan;
pub mod ui;

use aptscope_capture::open::OpenOptions;
use ratatui::crossterm::event::{self, DisableMouseCapture, EnableMouseCapture, Event};
use ratatui::crossterm::execute;
use ratatui::crossterm::terminal::{
    disable_raw_mode, enable_raw_mode, EnterAlternateScreen, LeaveAlternateScreen,
};
use ratatui::prelude::CrosstermBackend;
use ratatui::Terminal;
use std::io;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

fn restore_terminal() {
    let _ = disable_raw_mode();
    let _ = execute!(io::stdout(), DisableMouseCapture, LeaveAlternateScreen);
    let _ = execute!(io::stdout(), ratatui::crossterm::cursor::Show);
}

/// Restores the terminal when dropped (normal exit, error, or unwinding panic).
struct Guard;

impl Drop for Guard {
    fn drop(&mut self) {
        restore_terminal();
    }
}

/// Open `path` (any readable capture format) and run the interactive viewer until the user
/// quits. The first screen shows at once; the index builds in the background.
pub fn run(path: &str, opts: OpenOptions) -> io::Result<()> {
    run_as(path, opts, None)
}

/// [`run`], decoding as `proto` (APT or Elliptec) instead of detecting it when given.
pub fn run_as(
    path: &str,
    opts: OpenOptions,
    proto: Option<aptscope_dissector::detect::Proto>,
) -> io::Result<()> {
    run_with(path, opts, proto, Default::default())
}

/// [`run_as`], showing APT motion values also in physical units with the stage or scale of
/// `units` (devices with a built-in stage convert without it). With `opts.follow` set (a file
/// another process is still writing) the view is live: see [`run_live`].
pub fn run_with(
    path: &str,
    opts: OpenOptions,
    proto: Option<aptscope_dissector::detect::Proto>,
    units: aptscope_dissector::units::UnitsOpts,
) -> io::Result<()> {
    run_until(path, opts, proto, units, None)
}

/// [`run_with`] on a capture another thread or process is still writing (`opts.follow` set:
/// the index grows with the file), closing also when `quit` is set (the tap stopped); `note`
/// is shown after the file's name in the title (where the host program connects). The
/// timeline follows new records (LIVE / PAUSED in the status bar, `f` toggles, `G` resumes).
pub fn run_live(
    path: &str,
    note: Option<&str>,
    opts: OpenOptions,
    proto: Option<aptscope_dissector::detect::Proto>,
    units: aptscope_dissector::units::UnitsOpts,
    quit: &AtomicBool,
) -> io::Result<()> {
    run_until(path, opts, proto, units, Some((note, quit)))
}

fn run_until(
    path: &str,
    opts: OpenOptions,
    proto: Option<aptscope_dissector::detect::Proto>,
    units: aptscope_dissector::units::UnitsOpts,
    live: Option<(Option<&str>, &AtomicBool)>,
) -> io::Result<()> {
    let follow = opts.follow.is_some();
    let shared = index::spawn_with(path, opts, proto, units)?;
    let mut title = std::path::Path::new(path)
        .file_name()
        .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned());
    if let Some((Some(note), _)) = live {
        title = format!("{title} · {note}");
    }
    let mut app = app::App::new(shared, &title, true);
    app.set_live(follow || live.is_some());
    run_loop(app, live.map(|(_, q)| q))
}

/// Run the viewer on the records of the reader `open` returns (opened in the indexing thread:
/// readers are not `Send`), until the user quits; then the stop flag (`opts.cancel`, or the
/// index's own) is set, so a live reader blocked in `next_event` returns.
///
/// For a live source (a tap, `sim --view`, `view --follow`) give `opts.live = true`: the
/// timeline follows new records (LIVE / PAUSED in the status bar, `f` toggles, `G` resumes) and
/// every event the reader gives is shown at once. `title` names the source in the title bar.
pub fn run_source<F>(title: &str, open: F, opts: index::IndexOpts) -> io::Result<()>
where
    F: FnOnce() -> io::Result<index::Opened> + Send + 'static,
{
    let live = opts.live;
    let shared = index::spawn_source(open, opts)?;
    let mut app = app::App::new(shared, title, true);
    app.set_live(live);
    run_app(app)
}

/// The terminal loop on `app`: draw, handle keys and the mouse, until the user quits; then the
/// index's stop flag ([`index::Shared::cancel`]) is set. For a source fed another way than by a
/// [`aptscope_capture::model::Reader`] (a simulator's own traffic): make an
/// [`index::Shared`], feed an [`index::Indexer`] from a thread of your own (it publishes with
/// [`index::Indexer::flush`], [`index::Indexer::finish`] at the end), and run
/// `App::new(shared, title, true)` with [`app::App::set_live`] here.
pub fn run_app(app: app::App) -> io::Result<()> {
    run_loop(app, None)
}

/// The terminal UI draws on standard output and reads keys from the terminal: without one it
/// cannot run (a pipe, a file, a job with no controlling terminal). Say so, and what to use.
fn needs_terminal() -> io::Result<()> {
    use std::io::IsTerminal;
    let tty = std::fs::File::open("/dev/tty");
    if io::stdout().is_terminal() && tty.is_ok() {
        return Ok(());
    }
    Err(io::Error::other(
        "the terminal UI needs a terminal (standard output and a controlling terminal); \
         without one, `aptscope decode FILE` prints the timeline (`--json` for NDJSON)",
    ))
}

/// [`run_app`], closing also when `quit` is set.
fn run_loop(mut app: app::App, quit: Option<&AtomicBool>) -> io::Result<()> {
    let shared = app.shared.clone();
    needs_terminal()?;
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        restore_terminal();
        hook(info);
    }));
    enable_raw_mode()?;
    let _guard = Guard;
    execute!(io::stdout(), EnterAlternateScreen, EnableMouseCapture)?;
    let mut term = Terminal::new(CrosstermBackend::new(io::stdout()))?;
    term.clear()?;
    let result = (|| -> io::Result<()> {
        while !app.quit && !quit.is_some_and(|q| q.load(Ordering::Relaxed)) {
            term.draw(|f| ui::draw(f, &mut app))?;
            if event::poll(Duration::from_millis(100))? {
                // Handle everything queued before drawing again (fast key repeat stays smooth).
                loop {
                    match event::read()? {
                        Event::Key(k) => app.on_key(k),
                        Event::Mouse(m) => app.on_mouse(m),
                        _ => {}
                    }
                    if app.quit || !event::poll(Duration::ZERO)? {
                        break;
                    }
                }
            }
        }
        Ok(())
    })();
    shared.cancel.store(true, Ordering::Relaxed);
    drop(term);
    result
}
