//! The statistics view: what the capture is, then the scan's counts.

use super::{pane_block, Step};
use crate::app::App;
use ratatui::layout::Rect;
use ratatui::widgets::Paragraph;
use ratatui::Frame;

/// The statistics view's state.
#[derive(Debug, Clone, Default)]
pub struct Stats {
    /// First shown line.
    pub(crate) scroll: usize,
    /// The text (from the last update).
    text: String,
}

impl Stats {
    /// Before drawing: the `text` to show (see [`text`]), the scroll kept within it for a view
    /// `area`.
    pub(crate) fn update(&mut self, text: String, area: Rect) {
        let total = text.lines().count();
        let h = area.height.saturating_sub(1) as usize;
        self.scroll = self.scroll.min(total.saturating_sub(h));
        self.text = text;
    }

    /// Scroll.
    pub(crate) fn on_step(&mut self, step: Step) {
        self.scroll = match step {
            Step::By(d) => self.scroll.saturating_add_signed(d),
            Step::Top => 0,
            // The update clamps it to the last page.
            Step::Bottom => usize::MAX / 2,
            _ => self.scroll,
        };
    }

    /// Draw the view in `area`.
    pub(crate) fn draw(&self, f: &mut Frame<'_>, area: Rect) {
        let block = pane_block(" Statistics (q/Esc: back, j/k: scroll) ".into(), true);
        f.render_widget(
            Paragraph::new(self.text.as_str())
                .block(block)
                .scroll((self.scroll as u16, 0)),
            area,
        );
    }
}

/// The statistics text as of now: what the capture is, then the scan's counts.
pub(crate) fn text(app: &App) -> String {
    let scan = app.scan();
    let (text, scanned, done) = scan.state.lock().map_or((String::new(), 0, true), |s| {
        (s.stats.to_text(), s.scanned, s.done)
    });
    let mut head = String::new();
    if let Ok(ix) = app.shared().index.read() {
        head.push_str(&format!(
            "Capture: {} ({}), protocol {}{}\n",
            app.title(),
            ix.format,
            ix.proto.map_or("?", |p| p.name()),
            if ix.proto_certain {
                ""
            } else {
                " (best guess)"
            }
        ));
        for (i, s) in ix.streams.iter().enumerate() {
            head.push_str(&format!("Stream {i}: {s}\n"));
        }
        for (o, d) in &ix.file_diags {
            head.push_str(&format!("File problem @{o}: {d}\n"));
        }
        for u in &ix.units_notes {
            head.push_str(&format!("Physical {u}\n"));
        }
        if let Some(e) = &ix.error {
            head.push_str(&format!("Error: {e}\n"));
        }
    }
    if !app.filter_text().is_empty() {
        head.push_str(&format!("Filter: {}\n", app.filter_text()));
    }
    if !done {
        head.push_str(&format!("(counting… {scanned} records so far)\n"));
    }
    head.push('\n');
    head.push_str(&text);
    head
}
