//! Rendering the state: the timeline, detail tree and hex panes, the statistics and plot views,
//! the input/status bar and the help overlay. Only the visible rows are decoded.

use crate::app::{App, Areas, Input, Pane, TimeMode, View};
use crate::decode::{row, Node, NodeKind, Row, Way};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Clear, Dataset, GraphType, Paragraph, Wrap};
use ratatui::Frame;

/// The help text (also the `?` overlay).
pub const HELP: &[(&str, &str)] = &[
    ("j k ↑ ↓", "move (in the focused pane)"),
    ("g G Home End", "first / last"),
    ("PgUp PgDn ^u ^d", "page / half page"),
    ("Tab S-Tab", "next / previous pane"),
    (
        "Enter space h l",
        "detail: collapse / expand; pair line: jump",
    ),
    ("/", "display filter (Enter apply, Esc cancel)"),
    ("s", "search expression (filter language)"),
    ("n N", "next / previous match (no search: diagnostics)"),
    ("p", "jump to the paired request / reply"),
    (":", "go to record number"),
    ("t", "time: relative / delta / absolute"),
    ("f", "follow the end of the capture"),
    ("1 2 3", "timeline / statistics / plot"),
    ("mouse", "wheel scrolls, click selects"),
    ("? q ^C", "help / quit (q: back from a view)"),
];

fn dir_color(w: Way) -> Color {
    match w {
        Way::Out => Color::Cyan,
        Way::In => Color::Green,
        Way::Unknown => Color::Gray,
    }
}

fn family_color(f: &str) -> Color {
    match f {
        "MOT" | "motion" => Color::Yellow,
        "HW" | "query" => Color::Magenta,
        "PZ" | "PZMOT" | "KPZ" => Color::LightBlue,
        "LA" | "LD" | "TEC" => Color::LightRed,
        "QUAD" | "NT" | "KNA" | "KSG" => Color::LightCyan,
        "RACK" | "MOD" => Color::LightMagenta,
        _ => Color::White,
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
        draw_help(f, area);
    }
}

fn draw_title(f: &mut Frame<'_>, app: &App, area: Rect) {
    let (count, done, proto, format) =
        app.shared
            .index
            .read()
            .map_or((0, true, String::new(), String::new()), |ix| {
                (
                    ix.recs.len(),
                    ix.done,
                    ix.proto.map_or("?", |p| p.name()).to_string(),
                    ix.format.clone(),
                )
            });
    let mut s = format!(" aptscope  {} · {proto} · {count} records", app.title);
    if area.width >= 120 {
        s.push_str(&format!(" · {format}"));
    }
    if !done {
        s.push_str(&format!(
            "  [indexing {:.0}%]",
            app.shared.progress() * 100.0
        ));
    }
    if !app.filter_text.is_empty() {
        let (m, sdone) = app
            .scan
            .state
            .lock()
            .map_or((0, true), |st| (st.matches.len(), st.done));
        s.push_str(&format!(
            " · {m} shown{}",
            if sdone { "" } else { " (filtering…)" }
        ));
    }
    if app.follow {
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
        let hex_h = 3.min(area.height / 4).max(2);
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
    let inner = |r: Rect| Rect {
        y: r.y + 1,
        height: r.height.saturating_sub(1),
        ..r
    };
    app.areas = Areas {
        list: inner(list),
        detail: inner(detail),
        hex: inner(hex),
    };
    app.list_rows = inner(list).height as usize;
    app.detail_rows = inner(detail).height as usize;
    app.tick();
    draw_list(f, app, list);
    let lines = app.detail_lines();
    draw_detail(f, app, detail, &lines);
    draw_hex(f, app, hex, &lines);
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
    let h = inner.height as usize;
    // One row more above the first, for the Δ time of the first shown row.
    let from = app.top.saturating_sub(1);
    let ns = app.rows(from, h + (app.top - from));
    let Ok(ix) = app.shared.index.read() else {
        return;
    };
    let first = ix.first_ts;
    let rows: Vec<Option<Row>> = ns.iter().map(|n| row(&ix, *n)).collect();
    drop(ix);
    let nw = ns.last().map_or(6, |n| n.to_string().len().max(6));
    let wide = inner.width >= 110;
    let name_w = if wide { 30 } else { 23 };
    let mut lines = vec![];
    for (i, r) in rows.iter().enumerate() {
        let pos = from + i;
        if pos < app.top {
            continue;
        }
        let Some(r) = r else {
            lines.push(Line::from("?"));
            continue;
        };
        let prev = if i > 0 {
            rows[i - 1].as_ref().and_then(|p| p.ts)
        } else {
            None
        };
        let dc = dir_color(r.way);
        let mut spans = vec![
            Span::raw(format!("{:>nw$} ", r.n)),
            Span::styled(
                format!("{:>10} ", time_text(app.time_mode, r.ts, prev, first)),
                Style::new().fg(Color::DarkGray),
            ),
        ];
        if wide {
            spans.push(Span::raw(format!("{:<4}", r.proto)));
        }
        if r.garbage {
            spans.push(Span::styled(
                format!("!! {} ", r.diag),
                Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
            ));
            spans.push(Span::styled(
                r.fields.clone(),
                Style::new().fg(Color::DarkGray),
            ));
        } else {
            spans.push(Span::styled(
                format!("{} {:>5} → {:<5} ", r.way.arrow(), r.src, r.dst),
                Style::new().fg(dc),
            ));
            spans.push(Span::styled(
                format!("{:<name_w$} ", r.name),
                Style::new().fg(family_color(r.family)),
            ));
            if let Some(p) = r.pair {
                let t = if r.is_reply {
                    match r.latency_ns {
                        Some(l) => format!("↩#{p} {:.1}ms ", l as f64 / 1e6),
                        None => format!("↩#{p} "),
                    }
                } else {
                    format!("→#{p} ")
                };
                spans.push(Span::styled(t, Style::new().fg(Color::Blue)));
            }
            spans.push(Span::raw(r.fields.clone()));
            if !r.diag.is_empty() {
                spans.push(Span::styled(
                    format!("  !! {}", r.diag),
                    Style::new().fg(Color::Red).add_modifier(Modifier::BOLD),
                ));
            }
        }
        let mut line = Line::from(spans);
        if pos == app.sel {
            line = line.style(Style::new().add_modifier(Modifier::REVERSED));
        } else if !r.diag.is_empty() {
            line = line.style(Style::new().bg(Color::Rgb(60, 0, 0)));
        }
        lines.push(line);
    }
    if lines.is_empty() {
        let msg = if app.shared.index.read().is_ok_and(|ix| ix.done) {
            if app.filter_text.is_empty() {
                "(no records)"
            } else {
                "(no record matches the filter)"
            }
        } else {
            "(reading…)"
        };
        lines.push(Line::styled(msg, Style::new().fg(Color::DarkGray)));
    }
    f.render_widget(Paragraph::new(lines), inner);
}

fn draw_detail(f: &mut Frame<'_>, app: &App, area: Rect, lines: &[Node]) {
    let block = pane_block(" Detail ".into(), app.focus == Pane::Detail);
    let inner = block.inner(area);
    f.render_widget(block, area);
    let mut out = vec![];
    for (i, n) in lines
        .iter()
        .enumerate()
        .skip(app.detail_top)
        .take(inner.height as usize)
    {
        let marker = if n.children {
            if app.collapsed.contains(&n.id) {
                "▸ "
            } else {
                "▾ "
            }
        } else {
            "  "
        };
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
        let text = format!("{}{marker}{}", "  ".repeat(n.depth as usize), n.text);
        let mut line = Line::styled(text, style);
        if i == app.detail_sel && app.focus != Pane::List {
            line = line.patch_style(Style::new().add_modifier(Modifier::REVERSED));
        }
        out.push(line);
    }
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
    let ds = Dataset::default()
        .name(key.clone())
        .marker(Marker::Braille)
        .graph_type(GraphType::Line)
        .style(Style::new().fg(Color::Cyan))
        .data(&data);
    let fmt = |v: f64| format!("{}", aptscope_dissector::apt::round_sig(v));
    let title = format!(
        " Plot {}/{}: {key} ({} points)  j/k: series, q: back ",
        app.plot_page + 1,
        keys.len(),
        pts.len()
    );
    let chart = Chart::new(vec![ds])
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
    let s = match &app.message {
        Some(m) => m.clone(),
        None => " ?:help /:filter s,n,N:search p:pair ::goto t:time Tab:pane 2:stats 3:plot q:quit"
            .to_string(),
    };
    f.render_widget(
        Paragraph::new(s).style(Style::new().fg(Color::Black).bg(Color::Gray)),
        area,
    );
}

fn draw_help(f: &mut Frame<'_>, area: Rect) {
    let w = 64.min(area.width);
    let h = (HELP.len() as u16 + 2).min(area.height);
    let r = Rect {
        x: area.x + (area.width - w) / 2,
        y: area.y + (area.height - h) / 2,
        width: w,
        height: h,
    };
    let lines: Vec<Line> = HELP
        .iter()
        .map(|(k, d)| {
            Line::from(vec![
                Span::styled(format!(" {k:<16}"), Style::new().fg(Color::Yellow)),
                Span::raw(*d),
            ])
        })
        .collect();
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(lines).block(Block::bordered().title(" Keys (? or Esc to close) ")),
        r,
    );
}
