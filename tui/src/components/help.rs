//! The help overlay: the keys (from the one key list, [`crate::keys`]), the colouring rules
//! and examples of the filter language; it scrolls when the window is too small.

use crate::components::timeline::COLOURS;
use crate::keys::{self, Action, Move};
use ratatui::layout::Rect;
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph};
use ratatui::Frame;

/// The help overlay's state.
#[derive(Debug, Clone)]
pub struct Help {
    /// Whether it is shown.
    pub(crate) shown: bool,
    /// First shown line.
    pub(crate) scroll: usize,
    /// Lines it shows at once (from the last update).
    pub(crate) rows: usize,
    /// Where it is drawn and its lines (from the last update).
    frame: Rect,
    lines: Vec<Line<'static>>,
}

impl Default for Help {
    fn default() -> Self {
        Help {
            shown: false,
            scroll: 0,
            rows: 10,
            frame: Rect::default(),
            lines: vec![],
        }
    }
}

impl Help {
    /// Open it at its first line.
    pub(crate) fn open(&mut self) {
        self.shown = true;
        self.scroll = 0;
    }

    /// Scroll by `lines` (the mouse wheel); the update keeps it in range.
    pub(crate) fn scroll_by(&mut self, lines: isize) {
        self.scroll = self.scroll.saturating_add_signed(lines);
    }

    /// Handle a key's action while it is open.
    pub(crate) fn on_action(&mut self, a: Action) {
        let page = self.rows.max(1);
        match a {
            Action::CloseHelp => self.shown = false,
            Action::Move(Move::Down) => self.scroll += 1,
            Action::Move(Move::Up) => self.scroll = self.scroll.saturating_sub(1),
            Action::Move(Move::PageDown) => self.scroll += page,
            Action::Move(Move::PageUp) => self.scroll = self.scroll.saturating_sub(page),
            Action::Move(Move::Top) => self.scroll = 0,
            // The update clamps it to the last page.
            Action::Move(Move::Bottom) => self.scroll = usize::MAX / 2,
            _ => {}
        }
    }

    /// Before drawing on a screen `area`: its size and lines, the scroll kept within them.
    pub(crate) fn update(&mut self, area: Rect) {
        // As wide as the longest entry needs, within the screen; as tall as the text, else it
        // scrolls.
        let natural = keys::help_rows()
            .iter()
            .map(|(k, d)| (k.as_str(), *d))
            .chain(FILTER_EXAMPLES.iter().copied())
            .map(|(k, d)| (k.chars().count() + 1).max(KEY_W) + 1 + d.chars().count())
            .chain(COLOURS.iter().map(|c| KEY_W + 1 + c.what.chars().count()))
            .max()
            .unwrap_or(60)
            + 3;
        let w = (natural as u16).min(area.width.saturating_sub(2).max(area.width.min(20)));
        let lines = help_lines(w.saturating_sub(2) as usize);
        let h = (lines.len() as u16 + 2).min(area.height.saturating_sub(2).max(area.height.min(5)));
        self.frame = Rect {
            x: area.x + (area.width - w) / 2,
            y: area.y + (area.height - h) / 2,
            width: w,
            height: h,
        };
        self.rows = h.saturating_sub(2) as usize;
        self.scroll = self.scroll.min(lines.len().saturating_sub(self.rows));
        self.lines = lines;
    }

    /// Draw it (where the last update placed it).
    pub(crate) fn draw(&self, f: &mut Frame<'_>) {
        let (lines, rows, top) = (&self.lines, self.rows, self.scroll);
        let mut block = Block::bordered().title(" Help (? or Esc to close) ");
        if lines.len() > rows {
            let end = (top + rows).min(lines.len());
            let more = if end < lines.len() { "↓ " } else { "" };
            block = block.title_bottom(format!(
                " {more}lines {}–{end} of {} (j/k PgUp/PgDn) ",
                top + 1,
                lines.len()
            ));
        }
        let shown: Vec<Line> = lines.iter().skip(top).take(rows).cloned().collect();
        f.render_widget(Clear, self.frame);
        f.render_widget(Paragraph::new(shown).block(block), self.frame);
    }
}

/// Examples of the display-filter language, for the help overlay.
pub const FILTER_EXAMPLES: &[(&str, &str)] = &[
    ("apt.name ~ MOVE", "APT messages whose name matches a regex"),
    (
        "apt.position > 1000",
        "a field of the message (apt.fields.position)",
    ),
    (
        "apt.src == bay1 && apt.chan == 1",
        "addresses by name, channel",
    ),
    (
        "ell.cmd == PO",
        "Elliptec command (case: gs request, GS reply)",
    ),
    (
        "diag",
        "records with a diagnostic; unpaired: no reply or unsolicited",
    ),
    ("latency > 50ms", "replies slower than 50 ms"),
];

/// Width of the key column of the help overlay.
const KEY_W: usize = 18;

/// One help entry: the key (or a sample in its style) in a column `key_w` wide and its text,
/// wrapped to `width` columns under itself.
fn help_entry(
    out: &mut Vec<Line<'static>>,
    (width, key_w): (usize, usize),
    k: &str,
    ks: Style,
    d: &str,
) {
    let room = width.saturating_sub(key_w + 1).max(10);
    let mut rows: Vec<String> = vec![String::new()];
    for word in d.split(' ') {
        let used = rows.last().map_or(0, |r| r.chars().count());
        if used > 0 && used + 1 + word.chars().count() > room {
            rows.push(String::new());
        }
        if let Some(r) = rows.last_mut() {
            if !r.is_empty() {
                r.push(' ');
            }
            r.push_str(word);
        }
    }
    let k = format!(" {k}");
    let k_w = k.chars().count();
    // A key longer than its column gets a line of its own.
    let own_line = k_w > key_w;
    if own_line {
        out.push(Line::from(Span::styled(k.clone(), ks)));
    }
    for (i, r) in rows.into_iter().enumerate() {
        let mut spans = vec![];
        if i == 0 && !own_line {
            spans.push(Span::styled(k.clone(), ks));
            spans.push(Span::raw(" ".repeat(key_w + 1 - k_w)));
        } else {
            spans.push(Span::raw(" ".repeat(key_w + 1)));
        }
        spans.push(Span::raw(r));
        out.push(Line::from(spans));
    }
}

/// The help overlay's lines, wrapped to `width` columns: the keys, the colouring rules and
/// examples of the filter language.
pub fn help_lines(width: usize) -> Vec<Line<'static>> {
    let heading = Style::new().add_modifier(Modifier::BOLD | Modifier::UNDERLINED);
    let key = Style::new().fg(Color::Yellow);
    let cols = (width, KEY_W);
    let mut out = vec![Line::styled(" Keys", heading)];
    for (k, d) in keys::help_rows() {
        help_entry(&mut out, cols, &k, key, d);
    }
    out.push(Line::default());
    out.push(Line::styled(
        " Colours (a row takes the first rule that matches, as in Wireshark)",
        heading,
    ));
    for c in COLOURS {
        help_entry(&mut out, cols, c.name, c.style, c.what);
    }
    out.push(Line::default());
    out.push(Line::styled(
        " Display filters (/ and s; the language of aptscope decode -Y)",
        heading,
    ));
    // Examples are longer than keys: a wider column when the window has the room.
    let ex_w = FILTER_EXAMPLES
        .iter()
        .map(|(k, _)| k.chars().count() + 1)
        .max()
        .unwrap_or(KEY_W);
    let ex_cols = (width, if width >= ex_w + 30 { ex_w } else { KEY_W });
    for (k, d) in FILTER_EXAMPLES {
        help_entry(&mut out, ex_cols, k, key, d);
    }
    out
}
