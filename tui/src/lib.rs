//! aptscope-tui: the terminal UI (being written; this placeholder keeps the workspace building).
#![forbid(unsafe_code)]

/// Browse a capture in the terminal UI.
pub fn run(path: &str, _opts: aptscope_capture::open::OpenOptions) -> std::io::Result<()> {
    Err(std::io::Error::other(format!(
        "the terminal UI is not built yet ({path})"
    )))
}
