//! Rendering the state: the screen's layout, the title, and each part
//! ([`crate::components`]) drawing itself. Drawing reads the state only; [`draw`] first runs
//! the update step ([`App::update`]) that fits the state to the screen. Only the visible rows
//! are decoded.

use crate::app::{App, Pane, View};
pub use crate::components::filter_bar::live_marker;
pub use crate::components::help::{help_lines, FILTER_EXAMPLES};
pub use crate::components::plot::{segments, GAP_PERIODS};
pub use crate::components::timeline::{colour_rule, ColourRule, COLOURS};
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Style};
use ratatui::widgets::Paragraph;
use ratatui::Frame;

/// Where things go on a screen: the title line, the body (a view), the bar at the bottom, and
/// within the body the timeline view's three panes.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Screen {
    pub(crate) title: Rect,
    pub(crate) body: Rect,
    pub(crate) status: Rect,
    pub(crate) list: Rect,
    pub(crate) detail: Rect,
    pub(crate) hex: Rect,
}

impl Screen {
    /// The layout of a screen `area` whose bottom bar is `bar` rows high.
    pub(crate) fn of(area: Rect, bar: u16) -> Screen {
        let [title, body, status] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Min(1),
            Constraint::Length(bar),
        ])
        .areas(area);
        let (list, detail, hex) = panes(body);
        Screen {
            title,
            body,
            status,
            list,
            detail,
            hex,
        }
    }
}

/// The timeline view's panes: the timeline above the detail tree and the hex dump (side by
/// side when the window is wide).
fn panes(area: Rect) -> (Rect, Rect, Rect) {
    if area.width >= 140 {
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
    }
}

/// Draw the whole screen: the update step ([`App::update`]), then each part from its state.
pub fn draw(f: &mut Frame<'_>, app: &mut App) {
    app.update(f.area());
    render(f, app);
}

/// Draw the whole screen from the state as it is.
fn render(f: &mut Frame<'_>, app: &App) {
    let area = f.area();
    let parts = app.parts();
    let s = Screen::of(area, parts.bar.height());
    draw_title(f, app, s.title);
    match app.view() {
        View::Timeline => {
            parts.timeline.draw(f, app, s.list);
            parts.detail.draw(
                f,
                s.detail,
                app.focus() == Pane::Detail,
                app.focus() != Pane::List,
            );
            parts.hex.draw(f, app, s.hex);
        }
        View::Stats => parts.stats.draw(f, s.body),
        View::Plot => parts.plot.draw(f, app, s.body),
    }
    parts.bar.draw(f, app, s.status);
    if parts.help.shown {
        parts.help.draw(f);
    }
}

fn draw_title(f: &mut Frame<'_>, app: &App, area: Rect) {
    let (count, done, proto, format, problems) =
        app.shared()
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
    let mut s = format!(" aptscope  {} · {proto} · {count} records", app.title());
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
        if app.live() || app.shared().total.is_none() {
            s.push_str(" · LIVE");
        } else {
            s.push_str(&format!(
                "  [indexing {:.0}%]",
                app.shared().progress() * 100.0
            ));
        }
    }
    if !app.filter_text().is_empty() {
        // Filtering until the scan has caught up with the records there are (a live scan is
        // never "done": more may come).
        let (m, behind, scanned) = app.scan().state.lock().map_or((0, false, 0), |st| {
            let behind = !st.done && (st.scanned as usize) < count;
            (st.matches.len(), behind, st.scanned)
        });
        // How far the scan is: a field filter over a huge capture takes a while.
        let pct = (scanned as f64 * 100.0 / count.max(1) as f64).min(100.0);
        s.push_str(&format!(
            " · {m} shown{}",
            if behind {
                format!(" (filtering… {pct:.0}%)")
            } else {
                String::new()
            }
        ));
    }
    if app.following() && !app.live() {
        s.push_str("  [follow]");
    }
    let style = Style::new().fg(Color::Black).bg(Color::Blue);
    f.render_widget(Paragraph::new(s).style(style), area);
}
