//! aptscope-tui: the terminal UI of `aptscope view FILE`.
//!
//! Architecture (state → events → view): [`index`] builds a compact index of the capture in a
//! background thread; [`scan`] runs the display filter and statistics over it in another;
//! [`app::App`] holds the UI state and handles keys and mouse events without a terminal;
//! [`ui::draw`] renders the state, decoding only the visible rows ([`decode`]);
//! [`as_filter`] turns a detail line into a display filter.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod app;
pub mod as_filter;
pub mod decode;
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
/// `units` (devices with a built-in stage convert without it).
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
/// is shown after the file's name in the title (where the host program connects).
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
    let shared = index::spawn_with(path, opts, proto, units)?;
    let mut title = std::path::Path::new(path)
        .file_name()
        .map_or_else(|| path.to_string(), |n| n.to_string_lossy().into_owned());
    if let Some((Some(note), _)) = live {
        title = format!("{title} · {note}");
    }
    let quit = live.map(|(_, q)| q);
    let mut app = app::App::new(shared.clone(), &title, true);

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
