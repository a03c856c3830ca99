//! Rendering the state: the timeline, detail tree and hex panes, the statistics and plot views,
//! the input/status bar and the help overlay. Only the visible rows are decoded.

use crate::app::{App, Areas, Input, Pane, TimeMode, View};
use crate::decode::{row, Node, NodeKind, Row, Way};
use crate::index::{
    Index, Rec, F_DIAG, F_DUPLICATE, F_GARBAGE, F_IS_REPLY, F_NOT_FOR_MODEL, F_NO_REPLY,
    F_TRUNCATED, F_UNSOLICITED,
};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Clear, Dataset, GraphType, Paragraph, Wrap};
use ratatui::Frame;

/// The keys (the `?` overlay lists them).
pub const HELP: &[(&str, &str)] = &[
    ("j k ↑ ↓", "move (in the focused pane)"),
    ("g G Home End", "first / last"),
    ("PgUp PgDn ^u ^d", "page / half page"),
    ("Tab S-Tab", "next / previous pane"),
    (
        "Enter space h l",
        "detail: collapse / expand; pair line: jump",
    ),
    ("< >", "detail: scroll long lines left / right"),
    (
        "a",
        "apply the selected detail line as a display filter (in the timeline: its message)",
    ),
    (
        "A",
        "prepare it as a filter: edit it in the filter bar, Enter applies",
    ),
    (
        "&",
        "apply the current filter narrowed by the selected line",
    ),
    ("/", "display filter (Enter apply, Esc cancel)"),
    ("s", "search expression (filter language)"),
    ("n N", "next / previous match (no search: diagnostics)"),
    ("p", "jump to the paired request / reply"),
    (":", "go to record number"),
    ("t", "time: relative / delta / absolute"),
    (
        "f",
        "follow new records on/off (live: LIVE / PAUSED in the status bar; G resumes)",
    ),
    ("1 2 3", "timeline / statistics / plot"),
    ("mouse", "wheel scrolls, click selects"),
    ("? q ^C", "help / quit (q: back from a view)"),
];

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

/// Draw the whole screen.
pub fn draw(f: &mut Frame<'_>, app: &mut App) {
    let area = f.area();
    let input_h = match (&app.input, &app.filter_error) {
        (Input::Filter(_), Some(_)) => 2,
        _ => 1,
    };
    let [title, body, status] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Min(1),
        Constraint::Length(input_h),
    ])
    .areas(area);
    draw_title(f, app, title);
    match app.view {
        View::Timeline => draw_timeline_view(f, app, body),
        View::Stats => draw_stats(f, app, body),
        View::Plot => draw_plot(f, app, body),
    }
    draw_status(f, app, status);
    if app.help {
        draw_help(f, app, area);
    }
}

fn draw_title(f: &mut Frame<'_>, app: &App, area: Rect) {
    let (count, done, proto, format, problems) =
        app.shared
            .index
            .read()
            .map_or((0, true, String::new(), String::new(), 0), |ix| {
                let name = ix.proto.map_or("?", |p| p.name());
                // A guess says so, and how little of the input framed (random bytes: 0%).
                let proto = match (ix.proto_certain, ix.proto_share) {
                    (false, Some(share)) => format!("{name}? ({:.0}% frames)", share * 100.0),
                    _ => name.to_string(),
                };
                (
                    ix.recs.len(),
                    ix.done,
                    proto,
                    ix.format.clone(),
                    ix.file_diags.len(),
                )
            });
    let mut s = format!(" aptscope  {} · {proto} · {count} records", app.title);
    if problems > 0 {
        s.push_str(&format!(
            " · {problems} file problem{} (2: stats)",
            if problems == 1 { "" } else { "s" }
        ));
    }
    if area.width >= 120 {
        s.push_str(&format!(" · {format}"));
    }
    if !done {
        // A live source (a tap, a pipe, a growing file) has no end to count towards.
        if app.live || app.shared.total.is_none() {
            s.push_str(" · LIVE");
        } else {
            s.push_str(&format!(
                "  [indexing {:.0}%]",
                app.shared.progress() * 100.0
            ));
        }
    }
    if !app.filter_text.is_empty() {
        // Filtering until the scan has caught up with the records there are (a live scan is
        // never "done": more may come).
        let (m, behind) = app.scan.state.lock().map_or((0, false), |st| {
            (st.matches.len(), !st.done && (st.scanned as usize) < count)
        });
        s.push_str(&format!(
            " · {m} shown{}",
            if behind { " (filtering…)" } else { "" }
        ));
    }
    if app.follow && !app.live {
        s.push_str("  [follow]");
    }
    let style = Style::new().fg(Color::Black).bg(Color::Blue);
    f.render_widget(Paragraph::new(s).style(style), area);
}

fn pane_block(title: String, focused: bool) -> Block<'static> {
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

fn draw_timeline_view(f: &mut Frame<'_>, app: &mut App, area: Rect) {
    let wide = area.width >= 140;
    let (list, detail, hex) = if wide {
        let [list, bottom] =
            Layout::vertical([Constraint::Percentage(55), Constraint::Percentage(45)]).areas(area);
        let [detail, hex] =
            Layout::horizontal([Constraint::Min(40), Constraint::Length(78)]).areas(bottom);
        (list, detail, hex)
    } else {
        // The hex pane grows with the window (a sixth of it), so long frames show whole.
        let hex_h = (area.height / 6).max(3.min(area.height / 4).max(2));
        let rest = area.height.saturating_sub(hex_h);
        let list_h = (rest * 11 / 20).max(3);
        let [list, detail, hex] = Layout::vertical([
            Constraint::Length(list_h),
            Constraint::Min(2),
            Constraint::Length(hex_h),
        ])
        .areas(area);
        (list, detail, hex)
    };
    // Below the border line (and, for the timeline, the column headers).
    let below = |r: Rect, n: u16| Rect {
        y: r.y + n.min(r.height),
        height: r.height.saturating_sub(n),
        ..r
    };
    app.areas = Areas {
        list: below(list, 2),
        detail: below(detail, 1),
        hex: below(hex, 1),
    };
    app.list_rows = app.areas.list.height as usize;
    app.detail_rows = app.areas.detail.height as usize;
    app.tick();
    draw_list(f, app, list);
    let lines = app.detail_lines();
    draw_detail(f, app, detail, &lines);
    draw_hex(f, app, hex, &lines);
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
        let span = match (ix.first_ts, ix.recs.last().and_then(Rec::ts)) {
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

fn draw_list(f: &mut Frame<'_>, app: &App, area: Rect) {
    let len = app.len();
    let title = format!(
        " Timeline {}/{len}{} ",
        if len == 0 { 0 } else { app.sel + 1 },
        if app.filter_text.is_empty() {
            String::new()
        } else {
            format!("  filter: {}", app.filter_text)
        }
    );
    let block = pane_block(title, app.focus == Pane::List);
    let inner = block.inner(area);
    f.render_widget(block, area);
    if inner.height == 0 {
        return;
    }
    let [head, body] = Layout::vertical([Constraint::Length(1), Constraint::Min(0)]).areas(inner);
    let h = body.height as usize;
    // One row more above the first, for the Δ time of the first shown row.
    let from = app.top.saturating_sub(1);
    let ns = app.rows(from, h + (app.top - from));
    let Ok(ix) = app.shared.index.read() else {
        return;
    };
    let first = ix.first_ts;
    let cols = Columns::of(&ix, app.time_mode, inner.width);
    let rows: Vec<Option<(Row, Option<usize>, String)>> = ns
        .iter()
        .map(|n| {
            let r = row(&ix, *n)?;
            let rule = ix.rec(*n).and_then(|rec| colour_rule(rec, r.way));
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
        if pos < app.top {
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
            time_text(app.time_mode, r.ts, prev, first)
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
        if pos == app.sel {
            line = line.patch_style(Style::new().add_modifier(Modifier::REVERSED));
        }
        lines.push(line);
    }
    if lines.is_empty() {
        let (done, problems) = app
            .shared
            .index
            .read()
            .map_or((false, vec![]), |ix| (ix.done, ix.file_diags.clone()));
        let msg = if done {
            if app.filter_text.is_empty() {
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

fn draw_detail(f: &mut Frame<'_>, app: &mut App, area: Rect, lines: &[Node]) {
    let text_of = |n: &Node| {
        let marker = if n.children {
            if app.collapsed.contains(&n.id) {
                "▸ "
            } else {
                "▾ "
            }
        } else {
            "  "
        };
        format!("{}{marker}{}", "  ".repeat(n.depth as usize), n.text)
    };
    // Long lines scroll sideways (`<` `>`); the view keeps the scroll within the longest.
    let w = area.width as usize;
    let widest = lines
        .iter()
        .map(|n| text_of(n).chars().count())
        .max()
        .unwrap_or(0);
    let left = app.detail_left.min(widest.saturating_sub(w));
    let title = if left > 0 {
        format!(" Detail ◂{left} ")
    } else {
        " Detail ".to_string()
    };
    let block = pane_block(title, app.focus == Pane::Detail);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let mut out = vec![];
    for (i, n) in lines
        .iter()
        .enumerate()
        .skip(app.detail_top)
        .take(inner.height as usize)
    {
        let style = match n.kind {
            NodeKind::Section => Style::new().add_modifier(Modifier::BOLD),
            NodeKind::Item => Style::new(),
            NodeKind::FlagOn => Style::new().fg(Color::Green),
            NodeKind::FlagOff => Style::new().fg(Color::DarkGray),
            NodeKind::Link => Style::new()
                .fg(Color::Blue)
                .add_modifier(Modifier::UNDERLINED),
            NodeKind::Diag => Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
        };
        let full = text_of(n);
        let mut text: String = full.chars().skip(left).take(w).collect();
        // A line that goes on past the right edge ends in "…".
        if full.chars().count() > left + w {
            text.pop();
            text.push('…');
        }
        let mut line = Line::styled(text, style);
        if i == app.detail_sel && app.focus != Pane::List {
            line = line.patch_style(Style::new().add_modifier(Modifier::REVERSED));
        }
        out.push(line);
    }
    app.detail_left = left;
    f.render_widget(Paragraph::new(out), inner);
}

fn draw_hex(f: &mut Frame<'_>, app: &App, area: Rect, lines: &[Node]) {
    let block = pane_block(" Hex ".into(), app.focus == Pane::Hex);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let Some(n) = app.selected() else { return };
    let Ok(ix) = app.shared.index.read() else {
        return;
    };
    let Some(r) = ix.rec(n) else { return };
    let bytes = ix.bytes(r).to_vec();
    let base = r.offset;
    drop(ix);
    let hl = if app.focus == Pane::List {
        None
    } else {
        lines.get(app.detail_sel).and_then(|n| n.range)
    };
    // 6 (offset) + 3 per byte + 2 + 1 per byte: as many bytes as fit, 16 at most.
    let w = inner.width as usize;
    let bpr = [16usize, 8, 4]
        .into_iter()
        .find(|b| 8 + 4 * b <= w)
        .unwrap_or(4);
    let rows = bytes.len().div_ceil(bpr);
    let top = app.hex_top.min(rows.saturating_sub(1));
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

fn draw_stats(f: &mut Frame<'_>, app: &mut App, area: Rect) {
    let (text, scanned, done) = app.scan.state.lock().map_or((String::new(), 0, true), |s| {
        (s.stats.to_text(), s.scanned, s.done)
    });
    let mut head = String::new();
    if let Ok(ix) = app.shared.index.read() {
        head.push_str(&format!(
            "Capture: {} ({}), protocol {}{}\n",
            app.title,
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
    if !app.filter_text.is_empty() {
        head.push_str(&format!("Filter: {}\n", app.filter_text));
    }
    if !done {
        head.push_str(&format!("(counting… {scanned} records so far)\n"));
    }
    head.push('\n');
    head.push_str(&text);
    let total = head.lines().count();
    let h = area.height.saturating_sub(1) as usize;
    app.stats_scroll = app.stats_scroll.min(total.saturating_sub(h));
    let block = pane_block(" Statistics (q/Esc: back, j/k: scroll) ".into(), true);
    f.render_widget(
        Paragraph::new(head)
            .block(block)
            .scroll((app.stats_scroll as u16, 0)),
        area,
    );
}

fn draw_plot(f: &mut Frame<'_>, app: &mut App, area: Rect) {
    let Ok(ix) = app.shared.index.read() else {
        return;
    };
    let keys: Vec<&String> = ix.series.keys().collect();
    if keys.is_empty() {
        let block = pane_block(" Plot ".into(), true);
        f.render_widget(
            Paragraph::new(
                "No positions or velocities yet: they come from status updates \
                 (…STATUSUPDATE, GET_POSCOUNTER) and Elliptec position replies (PO).",
            )
            .wrap(Wrap { trim: true })
            .block(block),
            area,
        );
        return;
    }
    app.plot_page = app.plot_page.min(keys.len() - 1);
    let key = keys[app.plot_page];
    let pts = &ix.series[key];
    // Decimate to about two points per column.
    let max_pts = (area.width as usize * 2).max(2);
    let step = pts.len().div_ceil(max_pts).max(1);
    let data: Vec<(f64, f64)> = pts.iter().step_by(step).copied().collect();
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for (x, y) in &data {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(*y);
        y1 = y1.max(*y);
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        y1 = y0 + 1.0;
        y0 -= 1.0;
    }
    let xlabel = if ix.first_ts.is_some() {
        "time (s)"
    } else {
        "record"
    };
    // One line per stretch of data: a gap of many update periods is not drawn as a slow ramp.
    let datasets: Vec<Dataset<'_>> = segments(&data)
        .into_iter()
        .map(|seg| {
            Dataset::default()
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(Color::Cyan))
                .data(seg)
        })
        .collect();
    let fmt = |v: f64| format!("{}", aptscope_dissector::apt::round_sig(v));
    let title = format!(
        " Plot {}/{}: {key} ({} points)  j/k: series, q: back ",
        app.plot_page + 1,
        keys.len(),
        pts.len()
    );
    // The title names the series: no legend box over the data.
    let chart = Chart::new(datasets)
        .legend_position(None)
        .block(pane_block(title, true))
        .x_axis(
            Axis::default()
                .title(xlabel)
                .bounds([x0, x1])
                .labels(vec![Span::raw(fmt(x0)), Span::raw(fmt(x1))]),
        )
        .y_axis(
            Axis::default()
                .bounds([y0, y1])
                .labels(vec![Span::raw(fmt(y0)), Span::raw(fmt(y1))]),
        );
    f.render_widget(chart, area);
}

/// A series cut where it has no data for longer than [`GAP_PERIODS`] times its usual spacing
/// (the median step between points): each stretch is drawn as its own line.
pub fn segments(data: &[(f64, f64)]) -> Vec<&[(f64, f64)]> {
    let mut steps: Vec<f64> = data.windows(2).map(|w| w[1].0 - w[0].0).collect();
    if steps.is_empty() {
        return vec![data];
    }
    steps.sort_by(f64::total_cmp);
    let usual = steps[steps.len() / 2];
    let gap = GAP_PERIODS * usual;
    let mut out = vec![];
    let mut start = 0;
    for i in 1..data.len() {
        if usual > 0.0 && data[i].0 - data[i - 1].0 > gap {
            out.push(&data[start..i]);
            start = i;
        }
    }
    out.push(&data[start..]);
    out
}

/// How many usual update periods without data break a plotted line.
pub const GAP_PERIODS: f64 = 5.0;

fn draw_status(f: &mut Frame<'_>, app: &App, area: Rect) {
    let (prompt, text) = match &app.input {
        Input::Filter(s) => ("/", s.as_str()),
        Input::Goto(s) => (":", s.as_str()),
        Input::Search(s) => ("search: ", s.as_str()),
        Input::None => ("", ""),
    };
    if !prompt.is_empty() {
        let mut lines = vec![Line::from(vec![
            Span::styled(prompt, Style::new().fg(Color::Yellow)),
            Span::raw(text.to_string()),
            Span::styled("█", Style::new().fg(Color::Gray)),
        ])];
        if let (Input::Filter(_), Some(e)) = (&app.input, &app.filter_error) {
            let pad = " ".repeat(prompt.len() + e.column.saturating_sub(1));
            lines.push(Line::styled(
                format!("{pad}^ column {}: {}", e.column, e.msg),
                Style::new().fg(Color::Red),
            ));
        }
        f.render_widget(Paragraph::new(lines), area);
        return;
    }
    let marker = live_marker(app);
    let room =
        (area.width as usize).saturating_sub(marker.as_ref().map_or(0, |m| m.0.chars().count()));
    let s = match &app.message {
        Some(m) => m.clone(),
        None => {
            // As many hints as fit, the most useful first.
            // The other views come early: at 80 columns they used to be cut off.
            const HINTS: &[&str] = &[
                "?:help",
                "/:filter",
                "2:stats",
                "3:plot",
                "q:quit",
                "a,A:as filter",
                "s,n,N:search",
                "p:pair",
                "Tab:pane",
                "::goto",
                "t:time",
            ];
            let mut s = String::new();
            for h in HINTS {
                if s.chars().count() + 1 + h.chars().count() > room {
                    break;
                }
                s.push(' ');
                s.push_str(h);
            }
            s
        }
    };
    let bar = Style::new().fg(Color::Black).bg(Color::Gray);
    let mut spans = vec![];
    if let Some((text, style)) = marker {
        spans.push(Span::styled(text, style));
    }
    spans.push(Span::raw(s));
    f.render_widget(Paragraph::new(Line::from(spans)).style(bar), area);
}

/// The status bar's marker of a live source: LIVE while following, else PAUSED with the
/// count of records not yet seen.
pub fn live_marker(app: &App) -> Option<(String, Style)> {
    if !app.live {
        return None;
    }
    let stopped = app.shared.index.read().is_ok_and(|ix| ix.done);
    Some(if stopped {
        (
            " ENDED ".to_string(),
            Style::new().fg(Color::White).bg(Color::DarkGray),
        )
    } else if app.follow {
        (
            " LIVE ".to_string(),
            Style::new()
                .fg(Color::Black)
                .bg(Color::Green)
                .add_modifier(Modifier::BOLD),
        )
    } else {
        (
            format!(" PAUSED · {} new (f/G: follow) ", app.unseen()),
            Style::new()
                .fg(Color::Black)
                .bg(Color::Yellow)
                .add_modifier(Modifier::BOLD),
        )
    })
}

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
    for (k, d) in HELP {
        help_entry(&mut out, cols, k, key, d);
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

fn draw_help(f: &mut Frame<'_>, app: &mut App, area: Rect) {
    // As wide as the longest entry needs, within the screen; as tall as the text, else it
    // scrolls.
    let natural = HELP
        .iter()
        .chain(FILTER_EXAMPLES)
        .map(|(k, d)| (k.chars().count() + 1).max(KEY_W) + 1 + d.chars().count())
        .chain(COLOURS.iter().map(|c| KEY_W + 1 + c.what.chars().count()))
        .max()
        .unwrap_or(60)
        + 3;
    let w = (natural as u16).min(area.width.saturating_sub(2).max(area.width.min(20)));
    let lines = help_lines(w.saturating_sub(2) as usize);
    let h = (lines.len() as u16 + 2).min(area.height.saturating_sub(2).max(area.height.min(5)));
    let r = Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + (area.height - h) / 2,
        width: w,
        height: h,
    };
    let rows = h.saturating_sub(2) as usize;
    app.help_rows = rows;
    app.help_scroll = app.help_scroll.min(lines.len().saturating_sub(rows));
    let top = app.help_scroll;
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
    let shown: Vec<Line> = lines.into_iter().skip(top).take(rows).collect();
    f.render_widget(Clear, r);
    f.render_widget(Paragraph::new(shown).block(block), r);
}

#[cfg(test)]
mod tests {
    use super::segments;

    /// Status updates every 0.1 s, then nothing for 130 s, then more: two lines, not one with
    /// a ramp across the gap.
    #[test]
    fn a_gap_in_a_series_breaks_its_line() {
        let mut pts: Vec<(f64, f64)> = (0..50).map(|i| (i as f64 * 0.1, i as f64)).collect();
        pts.extend((0..50).map(|i| (135.0 + i as f64 * 0.1, 1000.0 + i as f64)));
        let segs = segments(&pts);
        assert_eq!(segs.len(), 2);
        assert_eq!((segs[0].len(), segs[1].len()), (50, 50));
        // Evenly spaced, or jittery within a few periods: one line.
        let jitter: Vec<(f64, f64)> = (0..50)
            .map(|i| (i as f64 * 0.1 + if i % 7 == 0 { 0.2 } else { 0.0 }, 0.0))
            .collect();
        assert_eq!(segments(&jitter).len(), 1);
        assert_eq!(segments(&[(1.0, 1.0)]).len(), 1);
    }
}
