//! The hex dump of the selected record, with the bytes of the selected detail line highlighted.

use super::{pane_block, Step};
use crate::app::{App, Pane};
use ratatui::layout::Rect;
use ratatui::style::{Color, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::Paragraph;
use ratatui::Frame;

/// The hex pane's state.
#[derive(Debug, Clone, Default)]
pub struct Hex {
    /// First shown row.
    pub(crate) top: usize,
}

impl Hex {
    /// Scroll a row at a time (a page too: frames are short).
    pub(crate) fn on_step(&mut self, step: Step) {
        match step {
            Step::By(d) => self.top = self.top.saturating_add_signed(d.signum()),
            Step::Top => self.top = 0,
            _ => {}
        }
    }

    /// Draw the selected record's bytes in `area` (those of the selected detail line
    /// highlighted unless the focus is on the timeline).
    pub(crate) fn draw(&self, f: &mut Frame<'_>, app: &App, area: Rect) {
        let block = pane_block(" Hex ".into(), app.focus() == Pane::Hex);
        let inner = block.inner(area);
        f.render_widget(block, area);
        let Some(n) = app.selected() else { return };
        let Ok(ix) = app.shared().index.read() else {
            return;
        };
        let Some(r) = ix.rec(n) else { return };
        let bytes = ix.bytes(&r).into_owned();
        let base = r.offset;
        drop(ix);
        let hl = if app.focus() == Pane::List {
            None
        } else {
            let detail = app.detail();
            detail.lines().get(detail.sel).and_then(|n| n.range)
        };
        // 6 (offset) + 3 per byte + 2 + 1 per byte: as many bytes as fit, 16 at most.
        let w = inner.width as usize;
        let bpr = [16usize, 8, 4]
            .into_iter()
            .find(|b| 8 + 4 * b <= w)
            .unwrap_or(4);
        let rows = bytes.len().div_ceil(bpr);
        let top = self.top.min(rows.saturating_sub(1));
        let in_hl = |i: usize| hl.is_some_and(|(s, l)| i >= s && i < s + l);
        let hls = Style::new().fg(Color::Black).bg(Color::Yellow);
        let mut out = vec![];
        for row_i in top..rows.min(top + inner.height as usize) {
            let start = row_i * bpr;
            let chunk = &bytes[start..(start + bpr).min(bytes.len())];
            let mut spans = vec![Span::styled(
                format!("{:06x} ", base + start as u64),
                Style::new().fg(Color::DarkGray),
            )];
            for (j, b) in chunk.iter().enumerate() {
                let st = if in_hl(start + j) { hls } else { Style::new() };
                spans.push(Span::styled(format!("{b:02x}"), st));
                spans.push(Span::raw(" "));
            }
            spans.push(Span::raw("   ".repeat(bpr - chunk.len())));
            spans.push(Span::raw(" "));
            for (j, b) in chunk.iter().enumerate() {
                let c = if b.is_ascii_graphic() || *b == b' ' {
                    *b as char
                } else {
                    '.'
                };
                let st = if in_hl(start + j) {
                    hls
                } else {
                    Style::new().fg(Color::Gray)
                };
                spans.push(Span::styled(c.to_string(), st));
            }
            out.push(Line::from(spans));
        }
        f.render_widget(Paragraph::new(out), inner);
    }
}
