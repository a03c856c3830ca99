//! The detail tree of the selected record: its lines (collapsible), the selected line, the
//! vertical and sideways scroll.

use super::{pane_block, Step};
use crate::decode::{Node, NodeKind};
use ratatui::layout::Rect;
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::Paragraph;
use ratatui::Frame;
use std::collections::HashSet;

/// The detail tree's state.
#[derive(Debug, Clone)]
pub struct Detail {
    /// Selected line (among visible lines).
    pub(crate) sel: usize,
    /// First shown line.
    pub(crate) top: usize,
    /// Columns the tree is scrolled to the right (`<` `>`).
    pub(crate) left: usize,
    /// Rows on screen (from the last update).
    pub(crate) rows: usize,
    /// Collapsed node ids.
    pub(crate) collapsed: HashSet<String>,
    /// The visible lines of the selected record (from the last update), for drawing.
    lines: Vec<Node>,
}

impl Default for Detail {
    fn default() -> Self {
        Detail {
            sel: 0,
            top: 0,
            left: 0,
            rows: 8,
            collapsed: HashSet::new(),
            lines: vec![],
        }
    }
}

impl Detail {
    /// The lines of a record's tree that show: the children of collapsed nodes left out.
    pub(crate) fn visible(&self, nodes: &[Node]) -> Vec<Node> {
        let mut out = vec![];
        let mut hide_below: Option<u16> = None;
        for node in nodes.iter() {
            if let Some(d) = hide_below {
                if node.depth > d {
                    continue;
                }
                hide_below = None;
            }
            if node.children && self.collapsed.contains(&node.id) {
                hide_below = Some(node.depth);
            }
            out.push(node.clone());
        }
        out
    }

    /// Another record is selected: start at its first line, at the left.
    pub(crate) fn reset(&mut self) {
        self.sel = 0;
        self.top = 0;
        self.left = 0;
    }

    /// Scroll so that the selected line is on screen.
    pub(crate) fn scroll_into_view(&mut self) {
        self.top = super::scroll_to(self.sel, self.top, self.rows);
    }

    /// A movement over the record's visible `lines`; true when the selected line is a link
    /// to open (the paired record) instead.
    pub(crate) fn on_step(&mut self, step: Step, lines: &[Node]) -> bool {
        let last = lines.len().saturating_sub(1);
        match step {
            Step::By(by) => self.sel = self.sel.saturating_add_signed(by).min(last),
            Step::Top => self.sel = 0,
            Step::Bottom => self.sel = last,
            Step::Toggle | Step::Collapse | Step::Expand => {
                if let Some(node) = lines.get(self.sel) {
                    if step == Step::Toggle && node.link.is_some() {
                        return true;
                    }
                    let collapse = match step {
                        Step::Collapse => Some(true),
                        Step::Expand => Some(false),
                        _ => None,
                    };
                    self.fold(&node.id, collapse);
                }
            }
            Step::None => {}
        }
        self.scroll_into_view();
        false
    }

    /// Collapse (`Some(true)`), expand (`Some(false)`) or toggle (`None`) node `id`.
    fn fold(&mut self, id: &str, collapse: Option<bool>) {
        let collapse = collapse.unwrap_or(!self.collapsed.contains(id));
        if collapse {
            self.collapsed.insert(id.to_string());
        } else {
            self.collapsed.remove(id);
        }
    }

    /// Before drawing: the visible `lines` of the selected record in a pane `width` columns
    /// wide (the sideways scroll stays within the longest line).
    pub(crate) fn update(&mut self, lines: Vec<Node>, width: usize) {
        let widest = lines
            .iter()
            .map(|n| self.text_of(n).chars().count())
            .max()
            .unwrap_or(0);
        self.left = self.left.min(widest.saturating_sub(width));
        self.lines = lines;
    }

    /// The visible lines as of the last update.
    pub(crate) fn lines(&self) -> &[Node] {
        &self.lines
    }

    /// A line as shown: indented, with its collapse marker.
    fn text_of(&self, n: &Node) -> String {
        let marker = if n.children {
            if self.collapsed.contains(&n.id) {
                "▸ "
            } else {
                "▾ "
            }
        } else {
            "  "
        };
        format!("{}{marker}{}", "  ".repeat(n.depth as usize), n.text)
    }

    /// Draw the tree in `area`; `focused`: the pane has the focus, `selecting`: the selected
    /// line is highlighted (the focus is not on the timeline).
    pub(crate) fn draw(&self, f: &mut Frame<'_>, area: Rect, focused: bool, selecting: bool) {
        // Long lines scroll sideways (`<` `>`).
        let w = area.width as usize;
        let left = self.left;
        let title = if left > 0 {
            format!(" Detail ◂{left} ")
        } else {
            " Detail ".to_string()
        };
        let block = pane_block(title, focused);
        let inner = block.inner(area);
        f.render_widget(block, area);
        let mut out = vec![];
        for (i, n) in self
            .lines
            .iter()
            .enumerate()
            .skip(self.top)
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
            let full = self.text_of(n);
            let mut text: String = full.chars().skip(left).take(w).collect();
            // A line that goes on past the right edge ends in "…".
            if full.chars().count() > left + w {
                text.pop();
                text.push('…');
            }
            let mut line = Line::styled(text, style);
            if i == self.sel && selecting {
                line = line.patch_style(Style::new().add_modifier(Modifier::REVERSED));
            }
            out.push(line);
        }
        f.render_widget(Paragraph::new(out), inner);
    }
}
