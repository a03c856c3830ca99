//! The viewer's parts, each owning its state: the timeline, the detail tree, the hex dump, the
//! filter (input and status) bar, the statistics and plot views and the help overlay.
//!
//! A part's state changes on keys and in an update step before each frame
//! ([`crate::app::App::update`]: the sizes of the screen, scrolls kept in range); drawing reads
//! it and writes nothing back.

pub mod detail;
pub mod filter_bar;
pub mod help;
pub mod hex;
pub mod plot;
pub mod stats;
pub mod timeline;

use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Span;
use ratatui::widgets::{Block, Borders};

/// What a movement key does where it applies (a page is the focused pane's height).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Step {
    /// Down (positive) or up by lines.
    By(isize),
    /// To the first line.
    Top,
    /// To the last line.
    Bottom,
    /// Open the selected line.
    Toggle,
    /// Collapse the selected node.
    Collapse,
    /// Expand the selected node.
    Expand,
    /// Nothing (a key that does nothing).
    None,
}

/// The first line `top` to show so that line `sel` is on a screen of `rows` lines (moved as
/// little as it must).
pub(crate) fn scroll_to(sel: usize, top: usize, rows: usize) -> usize {
    let h = rows.max(1);
    if sel < top {
        sel
    } else if sel >= top + h {
        sel + 1 - h
    } else {
        top
    }
}

/// A pane's frame: a top border with its title, highlighted when the pane has the focus.
pub(crate) fn pane_block(title: String, focused: bool) -> Block<'static> {
    let style = if focused {
        Style::new().fg(Color::Yellow).add_modifier(Modifier::BOLD)
    } else {
        Style::new().fg(Color::DarkGray)
    };
    Block::new()
        .borders(Borders::TOP)
        .border_style(style)
        .title(Span::styled(title, style))
}
