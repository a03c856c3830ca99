//! The timeline: one row per record (only the visible rows are decoded), coloured by rule, with
//! the selection, its scroll and follow mode.

use super::pane_block;
use crate::app::{App, Pane, TimeMode};
use crate::decode::{row, Row, Way};
use crate::index::{
    Index, Rec, F_DIAG, F_DUPLICATE, F_GARBAGE, F_IS_REPLY, F_NOT_FOR_MODEL, F_NO_REPLY,
    F_TRUNCATED, F_UNSOLICITED,
};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::Paragraph;
use ratatui::Frame;

/// The timeline's state.
#[derive(Debug, Clone)]
pub struct Timeline {
    /// Position of the selected row in the shown list.
    pub(crate) sel: usize,
    /// First shown row.
    pub(crate) top: usize,
    /// Keep the selection on the last record as the index grows (`f` toggles it; moving up
    /// stops it, `G`/End resumes it).
    pub(crate) follow: bool,
    /// Rows of the shown list seen so far: every row while following, else up to the last
    /// row that was on screen.
    pub(crate) seen: usize,
    /// Rows on screen (from the last update).
    pub(crate) rows: usize,
    /// Time column mode.
    pub(crate) time_mode: TimeMode,
}

impl Default for Timeline {
    fn default() -> Self {
        Timeline {
            sel: 0,
            top: 0,
            follow: false,
            seen: 0,
            rows: 10,
            time_mode: TimeMode::Relative,
        }
    }
}

impl Timeline {
    /// Scroll so that the selected row is on screen.
    pub(crate) fn scroll_into_view(&mut self) {
        self.top = super::scroll_to(self.sel, self.top, self.rows);
    }

    /// The next time mode (`t`).
    pub(crate) fn cycle_time(&mut self) {
        self.time_mode = match self.time_mode {
            TimeMode::Relative => TimeMode::Delta,
            TimeMode::Delta => TimeMode::Absolute,
            TimeMode::Absolute => TimeMode::Relative,
        }
    }

    /// Draw the timeline in `area` (its border, column headers and rows).
    pub(crate) fn draw(&self, f: &mut Frame<'_>, app: &App, area: Rect) {
        let len = app.len();
        let title = format!(
            " Timeline {}/{len}{} ",
            if len == 0 { 0 } else { self.sel + 1 },
            if app.filter_text().is_empty() {
                String::new()
            } else {
                format!("  filter: {}", app.filter_text())
            }
        );
        let block = pane_block(title, app.focus() == Pane::List);
        let inner = block.inner(area);
        f.render_widget(block, area);
        if inner.height == 0 {
            return;
        }
        let [head, body] =
            Layout::vertical([Constraint::Length(1), Constraint::Min(0)]).areas(inner);
        let h = body.height as usize;
        // One row more above the first, for the Δ time of the first shown row.
        let from = self.top.saturating_sub(1);
        let ns = app.rows(from, h + (self.top - from));
        let Ok(ix) = app.shared().index.read() else {
            return;
        };
        let first = ix.first_ts;
        let cols = Columns::of(&ix, self.time_mode, inner.width);
        let rows: Vec<Option<(Row, Option<usize>, String)>> = ns
            .iter()
            .map(|n| {
                let r = row(&ix, *n)?;
                let rule = ix.rec(*n).and_then(|rec| colour_rule(&rec, r.way));
                let port = if cols.port > 0 {
                    port_label(&ix, r.stream)
                } else {
                    String::new()
                };
                Some((r, rule, port))
            })
            .collect();
        drop(ix);
        f.render_widget(
            Paragraph::new(cols.header()).style(
                Style::new()
                    .fg(Color::White)
                    .bg(Color::DarkGray)
                    .add_modifier(Modifier::BOLD),
            ),
            head,
        );
        let (nw, tw, name_w) = (cols.n, cols.time, cols.name);
        let mut lines = vec![];
        for (i, r) in rows.iter().enumerate() {
            let pos = from + i;
            if pos < self.top {
                continue;
            }
            let Some((r, rule, port)) = r else {
                lines.push(Line::from("?"));
                continue;
            };
            let prev = if i > 0 {
                rows[i - 1].as_ref().and_then(|p| p.0.ts)
            } else {
                None
            };
            let mut spans = vec![Span::raw(format!(
                "{:>nw$} {:>tw$} ",
                r.n,
                time_text(self.time_mode, r.ts, prev, first)
            ))];
            if cols.proto {
                spans.push(Span::raw(format!("{:<6}", r.proto)));
            }
            if cols.port > 0 {
                spans.push(Span::raw(format!("{port:<w$} ", w = cols.port)));
            }
            // Garbage has no addresses, but the side it came from is known when captured.
            let (src, dst) = if r.garbage {
                match r.way {
                    Way::Out => ("host", "?"),
                    Way::In => ("?", "host"),
                    Way::Unknown => ("?", "?"),
                }
            } else {
                (r.src.as_str(), r.dst.as_str())
            };
            spans.push(Span::raw(format!(
                "{} {src:>5} → {dst:<5} {:<name_w$} ",
                r.way.arrow(),
                r.name
            )));
            let bold = Style::new().add_modifier(Modifier::BOLD);
            if r.garbage {
                spans.push(Span::styled(format!("!! {}  ", r.diag), bold));
                spans.push(Span::raw(r.fields.clone()));
            } else {
                if let Some(p) = r.pair {
                    let t = if r.is_reply {
                        match r.latency_ns {
                            Some(l) => format!("↩#{p} {:.1}ms ", l as f64 / 1e6),
                            None => format!("↩#{p} "),
                        }
                    } else {
                        format!("→#{p} ")
                    };
                    spans.push(Span::raw(t));
                }
                spans.push(Span::raw(r.fields.clone()));
                if !r.diag.is_empty() {
                    let gap = if r.fields.is_empty() && r.pair.is_none() {
                        ""
                    } else {
                        "  "
                    };
                    spans.push(Span::styled(format!("{gap}!! {}", r.diag), bold));
                }
            }
            let mut line = Line::from(spans).style(rule.map_or(Style::new(), |i| COLOURS[i].style));
            if pos == self.sel {
                line = line.patch_style(Style::new().add_modifier(Modifier::REVERSED));
            }
            lines.push(line);
        }
        if lines.is_empty() {
            let (done, problems) = app
                .shared()
                .index
                .read()
                .map_or((false, vec![]), |ix| (ix.done, ix.file_diags.clone()));
            let msg = if done {
                if app.filter_text().is_empty() {
                    "(no records)"
                } else {
                    "(no record matches the filter)"
                }
            } else {
                "(reading…)"
            };
            lines.push(Line::styled(msg, Style::new().fg(Color::DarkGray)));
            // A capture with nothing to show says why (another link type, a damaged file).
            for (o, d) in problems.iter().take(body.height.saturating_sub(1) as usize) {
                lines.push(Line::styled(
                    format!("file problem at byte {o}: {d}"),
                    Style::new().fg(Color::Red),
                ));
            }
        }
        f.render_widget(Paragraph::new(lines), body);
    }
}

/// A colouring rule of the timeline: rows take the style of the first rule that matches, as
/// Wireshark's default colouring rules do (errors first, then warnings, then kinds of traffic).
#[derive(Debug, Clone, Copy)]
pub struct ColourRule {
    /// Short name.
    pub name: &'static str,
    /// Which records it matches.
    pub what: &'static str,
    /// The row style.
    pub style: Style,
}

/// The colouring rules, in order (a row matching none keeps the terminal's colours).
pub const COLOURS: &[ColourRule] = &[
    ColourRule {
        name: "Errors",
        what: "garbage, truncated or malformed frames, unknown messages",
        style: Style::new()
            .fg(Color::LightRed)
            .bg(Color::Rgb(70, 0, 0))
            .add_modifier(Modifier::BOLD),
    },
    ColourRule {
        name: "Unsolicited",
        what: "replies no request asked for, second replies to one request",
        style: Style::new().fg(Color::Yellow).bg(Color::Rgb(70, 50, 0)),
    },
    ColourRule {
        name: "No reply",
        what: "requests that got no reply",
        style: Style::new()
            .fg(Color::LightMagenta)
            .bg(Color::Rgb(50, 0, 50)),
    },
    ColourRule {
        name: "Not for model",
        what: "messages the spec does not list for the device's model",
        style: Style::new().fg(Color::LightBlue).bg(Color::Rgb(0, 30, 70)),
    },
    ColourRule {
        name: "Replies",
        what: "answers to a request (↩#n: the request)",
        style: Style::new().fg(Color::Green),
    },
    ColourRule {
        name: "Requests",
        what: "host → device (→#n: the reply)",
        style: Style::new().fg(Color::Cyan),
    },
    ColourRule {
        name: "Device",
        what: "device → host without a request (status updates …)",
        style: Style::new().fg(Color::LightBlue),
    },
];

/// The colouring rule (index in [`COLOURS`]) of a record going `way`.
pub fn colour_rule(r: &Rec, way: Way) -> Option<usize> {
    if r.has(F_GARBAGE | F_TRUNCATED | F_DIAG) {
        Some(0)
    } else if r.has(F_UNSOLICITED | F_DUPLICATE) {
        Some(1)
    } else if r.has(F_NO_REPLY) {
        Some(2)
    } else if r.has(F_NOT_FOR_MODEL) {
        Some(3)
    } else if r.has(F_IS_REPLY) {
        Some(4)
    } else {
        match way {
            Way::Out => Some(5),
            Way::In => Some(6),
            Way::Unknown => None,
        }
    }
}

/// Time text for the time column.
fn time_text(mode: TimeMode, ts: Option<u64>, prev: Option<u64>, first: Option<u64>) -> String {
    let Some(t) = ts else {
        return "-".into();
    };
    match mode {
        TimeMode::Relative => format!("{:.6}", t.saturating_sub(first.unwrap_or(t)) as f64 / 1e9),
        TimeMode::Delta => match prev {
            Some(p) => format!("Δ{:.6}", t as f64 / 1e9 - p as f64 / 1e9),
            None => "Δ0.000000".into(),
        },
        TimeMode::Absolute => {
            let secs = t / 1_000_000_000;
            let us = (t % 1_000_000_000) / 1000;
            let d = secs % 86_400;
            format!("{:02}:{:02}:{:02}.{us:06}", d / 3600, d / 60 % 60, d % 60)
        }
    }
}

/// Widths of the timeline columns: sized for the whole capture (its record count and time
/// span), so rows do not shift as the view scrolls.
struct Columns {
    /// Record number.
    n: usize,
    /// Time.
    time: usize,
    /// Whether the protocol column is shown.
    proto: bool,
    /// Message name.
    name: usize,
    /// Width of the stream (port) column: 0 when the capture has one stream.
    port: usize,
}

/// Short label of stream `i` for the timeline: the last part of its name (`ttyUSB0`), else its
/// index.
fn port_label(ix: &Index, i: u16) -> String {
    match ix.streams.get(i as usize).filter(|s| !s.is_empty()) {
        Some(s) => {
            let tail = s.rsplit(['/', '\\']).next().unwrap_or(s);
            tail.chars().take(PORT_MAX).collect()
        }
        None => format!("#{i}"),
    }
}

/// Widest stream label.
const PORT_MAX: usize = 12;

impl Columns {
    fn of(ix: &Index, mode: TimeMode, width: u16) -> Self {
        let n = ix.recs.len().max(1).to_string().len().max(3);
        let span = match (ix.first_ts, ix.recs.last().and_then(|r| r.ts())) {
            (Some(a), Some(b)) => Some(b.saturating_sub(a)),
            _ => None,
        };
        let rel = span.map_or(0, |s| format!("{:.6}", s as f64 / 1e9).len().max(8));
        let time = match (span, mode) {
            (None, _) => 4,
            (_, TimeMode::Absolute) => 15,
            (_, TimeMode::Relative) => rel,
            // "Δ" and a sign.
            (_, TimeMode::Delta) => rel + 2,
        };
        let proto = width >= 110;
        let port = if ix.multi_stream() {
            (0..64u16)
                .filter(|i| ix.streams_seen & (1 << i) != 0)
                .map(|i| port_label(ix, i).chars().count())
                .max()
                .unwrap_or(2)
                .max(4)
        } else {
            0
        };
        Columns {
            n,
            time,
            proto,
            name: if proto { 30 } else { 23 },
            port,
        }
    }

    /// The header row.
    fn header(&self) -> String {
        let (nw, tw, name_w) = (self.n, self.time, self.name);
        let mut s = format!("{:>nw$} {:>tw$} ", "No.", "Time");
        if self.proto {
            s.push_str("Proto ");
        }
        if self.port > 0 {
            s.push_str(&format!("{:<w$} ", "Port", w = self.port));
        }
        s.push_str(&format!(
            "  {:>5} → {:<5} {:<name_w$} Info",
            "Src", "Dst", "Message"
        ));
        s
    }
}
