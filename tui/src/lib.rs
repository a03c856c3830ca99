//! aptscope-tui: the terminal UI of `aptscope view FILE`.
//!
//! Architecture (state → events → view): [`index`] builds a compact index of the capture in a
//! background thread from the one decode chain's records; [`scan`] runs the display filter and
//! statistics over it in another, reading the compact records through [`fields::View`];
//! [`app::App`] holds the UI state, made of parts ([`components`]: timeline, detail tree, hex,
//! filter bar, statistics, plot, help), and handles keys and mouse events without a terminal,
//! looking keys up in the one key list ([`keys`]) that also writes the help and the status
//! bar's hints; [`ui::draw`] fits the state to the screen, then each part draws itself from its
//! state, decoding only the visible rows ([`decode`]); [`as_filter`] turns a detail line into a
//! display filter.
//!
//! [`run`] opens a [`Source`]: a file, a reader, or an app fed another way. Live sources (a
//! tap, a simulator, a file still being written) grow the index while the view is open, the
//! timeline follows it (LIVE / PAUSED in the status bar) and filters and statistics extend as
//! records arrive.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod app;
pub mod as_filter;
pub mod components;
pub mod decode;
pub mod fields;
pub mod index;
pub mod keys;
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

/// What the viewer shows.
pub enum Source<'a> {
    /// A capture file (any readable format). The first screen shows at once; the index builds
    /// in the background. With `opts.follow` set (a file another process is still writing) the
    /// view is live, as it is when [`Options::quit`] is given (the file a tap writes): the
    /// index grows with the file and the timeline follows it.
    File {
        /// The file.
        path: &'a str,
        /// How to open it.
        opts: OpenOptions,
        /// Decode as this protocol (APT or Elliptec) instead of detecting it.
        proto: Option<aptscope_dissector::detect::Proto>,
        /// Show APT motion values also in physical units with this stage or scale (devices
        /// with a built-in stage convert without it).
        units: aptscope_dissector::units::UnitsOpts,
    },
    /// The records of the reader `open` returns (opened in the indexing thread: readers are
    /// not `Send`). When the user quits the stop flag (`opts.cancel`, or the index's own) is
    /// set, so a live reader blocked in `next_event` returns. For a live source (a tap,
    /// `sim --view`, `view --follow`) give `opts.live = true`: every event the reader gives is
    /// shown at once.
    Reader {
        /// Names the source in the title bar.
        title: &'a str,
        /// Opens the reader.
        open: Box<dyn FnOnce() -> io::Result<index::Opened> + Send>,
        /// How to index it.
        opts: index::IndexOpts,
    },
    /// An app over a source fed another way than by a
    /// [`aptscope_capture::model::Reader`] (a simulator's own traffic): make an
    /// [`index::Shared`], feed an [`index::Indexer`] from a thread of your own (it publishes
    /// with [`index::Indexer::flush`], [`index::Indexer::finish`] at the end), and give
    /// `App::new(shared, title, true)` with [`app::App::set_live`].
    App(Box<app::App>),
}

/// How the viewer runs, besides what it shows.
#[derive(Debug, Default, Clone, Copy)]
pub struct Options<'a> {
    /// Shown after the source's name in the title (where the host program connects).
    pub note: Option<&'a str>,
    /// Close also when this is set (the tap stopped).
    pub quit: Option<&'a AtomicBool>,
}

/// Run the interactive viewer on `source` until the user quits (or [`Options::quit`] is set);
/// then the index's stop flag ([`index::Shared::cancel`]) is set. A live view follows new
/// records (LIVE / PAUSED in the status bar, `f` toggles, `G` resumes) and filters and
/// statistics extend as records arrive.
pub fn run(source: Source<'_>, options: Options<'_>) -> io::Result<()> {
    let with_note = |title: String| match options.note {
        Some(note) => format!("{title} · {note}"),
        None => title,
    };
    let app = match source {
        Source::File {
            path,
            opts,
            proto,
            units,
        } => {
            let live = opts.follow.is_some() || options.quit.is_some();
            // A file still being written is not cached.
            let cache = if live { None } else { index::default_cache() };
            let shared = index::spawn_cached(path, opts, proto, units, cache)?;
            let title = std::path::Path::new(path)
                .file_name()
                .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned());
            let mut app = app::App::new(shared, &with_note(title), true);
            app.set_live(live);
            app
        }
        Source::Reader { title, open, opts } => {
            let live = opts.live;
            let shared = index::spawn_source(open, opts)?;
            let mut app = app::App::new(shared, &with_note(title.to_string()), true);
            app.set_live(live);
            app
        }
        Source::App(app) => *app,
    };
    run_loop(app, options.quit)
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

/// The terminal loop on `app`: draw, handle keys and the mouse, until the user quits or `quit`
/// is set; then the index's stop flag is set.
fn run_loop(mut app: app::App, quit: Option<&AtomicBool>) -> io::Result<()> {
    let shared = app.shared().clone();
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
        while !app.should_quit() && !quit.is_some_and(|q| q.load(Ordering::Relaxed)) {
            term.draw(|f| ui::draw(f, &mut app))?;
            if event::poll(Duration::from_millis(100))? {
                // Handle everything queued before drawing again (fast key repeat stays smooth).
                loop {
                    match event::read()? {
                        Event::Key(k) => app.on_key(k),
                        Event::Mouse(m) => app.on_mouse(m),
                        _ => {}
                    }
                    if app.should_quit() || !event::poll(Duration::ZERO)? {
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
