//! The bar at the bottom: the line being edited (display filter, search, go to) with the
//! filter's error, else the live marker and a message or the key hints; it keeps the applied
//! filter and search.

use crate::app::{App, Input};
use crate::keys::{self, Action};
use aptscope_dissector::filter::{Filter, FilterError};
use ratatui::crossterm::event::KeyCode;
use ratatui::layout::Rect;
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::Paragraph;
use ratatui::Frame;

/// The bar's state.
#[derive(Debug, Clone)]
pub struct FilterBar {
    /// The line being edited.
    pub(crate) input: Input,
    /// The applied display filter text (empty: none).
    pub(crate) filter_text: String,
    /// The error of the filter being typed, if any.
    pub(crate) filter_error: Option<FilterError>,
    /// The search expression.
    pub(crate) search: Option<(String, Filter)>,
    /// A one-line message.
    pub(crate) message: Option<String>,
}

impl Default for FilterBar {
    fn default() -> Self {
        FilterBar {
            input: Input::None,
            filter_text: String::new(),
            filter_error: None,
            search: None,
            message: None,
        }
    }
}

impl FilterBar {
    /// Rows the bar needs: two when the filter being typed has an error to show.
    pub(crate) fn height(&self) -> u16 {
        match (&self.input, &self.filter_error) {
            (Input::Filter(_), Some(_)) => 2,
            _ => 1,
        }
    }

    /// Edit the line being typed with a key (`action`: what the key list says it does there);
    /// true when the line is to be applied (Enter).
    pub(crate) fn edit(&mut self, action: Option<Action>, code: KeyCode) -> bool {
        let text = match &mut self.input {
            Input::Filter(s) | Input::Goto(s) | Input::Search(s) => s,
            Input::None => return false,
        };
        match (action, code) {
            (Some(Action::Cancel), _) => {
                self.input = Input::None;
                self.filter_error = None;
            }
            (Some(Action::DeleteChar), _) => {
                text.pop();
            }
            (Some(Action::ClearLine), _) => text.clear(),
            (Some(Action::Commit), _) => return true,
            (_, KeyCode::Char(c)) => text.push(c),
            _ => {}
        }
        // Live feedback on the filter being typed.
        if let Input::Filter(s) = &self.input {
            self.filter_error = Filter::parse(s).err();
        }
        false
    }

    /// Draw the bar in `area`: the line being edited (with the filter's error under it), else
    /// the live marker and the message or as many key hints as fit.
    pub(crate) fn draw(&self, f: &mut Frame<'_>, app: &App, area: Rect) {
        let (prompt, text) = match &self.input {
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
            if let (Input::Filter(_), Some(e)) = (&self.input, &self.filter_error) {
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
        let room = (area.width as usize)
            .saturating_sub(marker.as_ref().map_or(0, |m| m.0.chars().count()));
        let s = match &self.message {
            Some(m) => m.clone(),
            None => {
                // As many hints as fit, the most useful first.
                let mut s = String::new();
                for h in keys::hints() {
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
}

/// The status bar's marker of a live source: LIVE while following, else PAUSED with the
/// count of records not yet seen.
pub fn live_marker(app: &App) -> Option<(String, Style)> {
    if !app.live() {
        return None;
    }
    let stopped = app.shared().index.read().is_ok_and(|ix| ix.done);
    Some(if stopped {
        (
            " ENDED ".to_string(),
            Style::new().fg(Color::White).bg(Color::DarkGray),
        )
    } else if app.following() {
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
