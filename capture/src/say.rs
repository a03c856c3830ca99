//! Where a live tool's progress lines go, passed to whoever prints them (no global switch).

use std::fmt;
use std::io::Write as _;

/// Whether progress lines (device gone, signal received, the statistics …) are said on
/// standard error. An extcap says nothing there (Wireshark shows anything on it as an error);
/// a live view holds them back while it has the terminal.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Say {
    /// On standard error (ignoring a closed or failing one, as [`note!`](crate::note) does).
    #[default]
    Stderr,
    /// Nowhere.
    Nothing,
}

impl Say {
    /// Say one line (`say.line(format_args!(…))`).
    pub fn line(self, args: fmt::Arguments<'_>) {
        if self == Say::Stderr {
            let _ = writeln!(std::io::stderr(), "{args}");
        }
    }
}
