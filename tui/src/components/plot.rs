//! The plot view: positions and velocities over time, one series per page.

use super::{pane_block, Step};
use crate::app::App;
use ratatui::layout::Rect;
use ratatui::style::{Color, Style};
use ratatui::symbols::Marker;
use ratatui::text::Span;
use ratatui::widgets::{Axis, Chart, Dataset, GraphType, Paragraph, Wrap};
use ratatui::Frame;

/// The plot view's state.
#[derive(Debug, Clone, Default)]
pub struct Plot {
    /// Which series is shown.
    pub(crate) page: usize,
}

impl Plot {
    /// Before drawing: the page kept within the `series` there are (when there are any).
    pub(crate) fn update(&mut self, series: usize) {
        if series > 0 {
            self.page = self.page.min(series - 1);
        }
    }

    /// Turn the page: down for the next series, up for the previous.
    pub(crate) fn on_step(&mut self, step: Step) {
        match step {
            Step::By(d) if d > 0 => self.page += 1,
            Step::By(_) => self.page = self.page.saturating_sub(1),
            Step::Top => self.page = 0,
            _ => {}
        }
    }

    /// Draw the shown series in `area`.
    pub(crate) fn draw(&self, f: &mut Frame<'_>, app: &App, area: Rect) {
        let Ok(ix) = app.shared().index.read() else {
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
        // The update kept the page in range (series are never removed).
        let page = self.page.min(keys.len() - 1);
        let key = keys[page];
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
            page + 1,
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
