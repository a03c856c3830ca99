//! Application state and event handling (no terminal needed): keys and mouse events change
//! the state; [`crate::ui::draw`] renders it.

use crate::as_filter;
use crate::decode::{tree, Node};
use crate::fields;
use crate::index::Shared;
use crate::scan::Scan;
use aptscope_dissector::filter::{Filter, FilterError};
use ratatui::crossterm::event::{
    KeyCode, KeyEvent, KeyModifiers, MouseButton, MouseEvent, MouseEventKind,
};
use ratatui::layout::{Position, Rect};
use std::collections::HashSet;
use std::sync::Arc;

/// Which screen is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// Timeline, detail tree and hex.
    Timeline,
    /// Statistics.
    Stats,
    /// Positions and velocities over time.
    Plot,
}

/// Which pane of the timeline view has the focus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pane {
    /// The timeline.
    List,
    /// The detail tree.
    Detail,
    /// The hex dump.
    Hex,
}

/// How times are shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeMode {
    /// Seconds since the first record.
    Relative,
    /// Time since the previous shown record.
    Delta,
    /// Wall-clock time (UTC) of the capture.
    Absolute,
}

/// A line being edited at the bottom of the screen.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Input {
    /// No input line.
    None,
    /// The display filter (`/`).
    Filter(String),
    /// A record number to go to (`:`).
    Goto(String),
    /// A search expression (`s`), display-filter language; `n`/`N` find the next/previous.
    Search(String),
}

/// What to do with the filter built from the selected line ([`App::selected_as_filter`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AsFilter {
    /// Apply it (Wireshark's "Apply as Filter → Selected").
    Apply,
    /// Put it in the filter bar to edit ("Prepare as Filter → Selected").
    Prepare,
    /// Apply the current filter narrowed by it ("Apply as Filter → … and Selected").
    And,
}

/// Screen areas of the last draw, for mouse events.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Areas {
    /// Timeline rows (inside the border).
    pub list: Rect,
    /// Detail rows.
    pub detail: Rect,
    /// Hex rows.
    pub hex: Rect,
}

/// The whole UI state.
pub struct App {
    /// The capture index.
    pub shared: Arc<Shared>,
    /// The filter/statistics scan.
    pub scan: Arc<Scan>,
    /// Scans run in background threads (false in tests: synchronous).
    pub background: bool,
    /// Screen.
    pub view: View,
    /// Focused pane.
    pub focus: Pane,
    /// Input line.
    pub input: Input,
    /// Position of the selected row in the shown list.
    pub sel: usize,
    /// First shown row of the timeline.
    pub top: usize,
    /// Keep the selection on the last record as the index grows (`f` toggles it; moving up
    /// stops it, `G`/End resumes it).
    pub follow: bool,
    /// The source is live: the status bar shows LIVE (following) or PAUSED with the count of
    /// records not yet seen.
    pub live: bool,
    /// Rows of the shown list seen so far: every row while following, else up to the last
    /// row that was on screen.
    pub seen: usize,
    /// Time column mode.
    pub time_mode: TimeMode,
    /// The applied display filter text (empty: none).
    pub filter_text: String,
    /// The error of the filter being typed, if any.
    pub filter_error: Option<FilterError>,
    /// The search expression.
    pub search: Option<(String, Filter)>,
    /// Selected line of the detail tree (among visible lines).
    pub detail_sel: usize,
    /// First shown line of the detail tree.
    pub detail_top: usize,
    /// Collapsed tree node ids.
    pub collapsed: HashSet<String>,
    /// First shown hex row.
    pub hex_top: usize,
    /// Columns the detail tree is scrolled to the right (`<` `>`).
    pub detail_left: usize,
    /// Help overlay shown.
    pub help: bool,
    /// First shown line of the help overlay (it scrolls when the window is too small).
    pub help_scroll: usize,
    /// Lines of the help overlay at the last draw.
    pub help_rows: usize,
    /// Quit requested.
    pub quit: bool,
    /// A one-line message for the status bar.
    pub message: Option<String>,
    /// Rows of the timeline at the last draw.
    pub list_rows: usize,
    /// Rows of the detail pane at the last draw.
    pub detail_rows: usize,
    /// Scroll of the statistics view.
    pub stats_scroll: usize,
    /// Which plot series page is shown.
    pub plot_page: usize,
    /// Screen areas of the last draw.
    pub areas: Areas,
    /// File name, for the title.
    pub title: String,
}

impl App {
    /// A new UI over an index (being built or complete).
    pub fn new(shared: Arc<Shared>, title: &str, background: bool) -> Self {
        let scan = Arc::new(Scan::default());
        let app = App {
            shared,
            scan,
            background,
            view: View::Timeline,
            focus: Pane::List,
            input: Input::None,
            sel: 0,
            top: 0,
            follow: false,
            live: false,
            seen: 0,
            time_mode: TimeMode::Relative,
            filter_text: String::new(),
            filter_error: None,
            search: None,
            detail_sel: 0,
            detail_top: 0,
            collapsed: HashSet::new(),
            hex_top: 0,
            detail_left: 0,
            help: false,
            help_scroll: 0,
            help_rows: 10,
            quit: false,
            message: None,
            list_rows: 10,
            detail_rows: 8,
            stats_scroll: 0,
            plot_page: 0,
            areas: Areas::default(),
            title: title.to_string(),
        };
        app.scan.start(app.shared.clone(), None, app.background);
        app
    }

    /// Say whether the source is live (a tap, a simulator, a file being written): a live view
    /// follows new records from the start and shows LIVE / PAUSED in the status bar.
    pub fn set_live(&mut self, live: bool) {
        self.live = live;
        self.shared
            .live
            .store(live, std::sync::atomic::Ordering::Relaxed);
        if live {
            self.follow = true;
        }
    }

    /// Rows of the shown list not seen yet (arrived below the screen while paused).
    pub fn unseen(&self) -> usize {
        self.len().saturating_sub(self.seen)
    }

    /// Number of rows in the shown list (all records, or those the filter matches).
    pub fn len(&self) -> usize {
        if self.filter_text.is_empty() {
            self.shared.index.read().map_or(0, |ix| ix.recs.len())
        } else {
            self.scan.state.lock().map_or(0, |s| s.matches.len())
        }
    }

    /// Whether the shown list is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Record numbers of the shown rows `from..from+count`.
    pub fn rows(&self, from: usize, count: usize) -> Vec<u64> {
        if self.filter_text.is_empty() {
            let len = self.len();
            (from..(from + count).min(len))
                .map(|i| i as u64 + 1)
                .collect()
        } else {
            self.scan.state.lock().map_or(vec![], |s| {
                s.matches.iter().skip(from).take(count).copied().collect()
            })
        }
    }

    /// The selected record number.
    pub fn selected(&self) -> Option<u64> {
        self.rows(self.sel, 1).first().copied()
    }

    /// Position of record `n` in the shown list (or of the first shown record after it).
    fn position_of(&self, n: u64) -> Option<usize> {
        if self.filter_text.is_empty() {
            let len = self.len() as u64;
            return (n >= 1 && n <= len).then_some(n as usize - 1);
        }
        let s = self.scan.state.lock().ok()?;
        let p = s.matches.partition_point(|m| *m < n);
        (p < s.matches.len()).then_some(p)
    }

    /// Select row `pos` (clamped), keeping it in view.
    pub fn select(&mut self, pos: usize) {
        let len = self.len();
        let new = pos.min(len.saturating_sub(1));
        if new != self.sel {
            self.detail_sel = 0;
            self.detail_top = 0;
            self.hex_top = 0;
            self.detail_left = 0;
        }
        self.sel = new;
        self.scroll_into_view();
    }

    fn scroll_into_view(&mut self) {
        let h = self.list_rows.max(1);
        if self.sel < self.top {
            self.top = self.sel;
        } else if self.sel >= self.top + h {
            self.top = self.sel + 1 - h;
        }
    }

    /// Go to record `n` (or the next shown one).
    pub fn goto(&mut self, n: u64) {
        match self.position_of(n) {
            Some(p) => {
                self.follow = false;
                self.select(p);
                if self.selected() != Some(n) {
                    self.message = Some(format!("#{n} is not shown; nearest after it selected"));
                }
            }
            None => self.message = Some(format!("no record #{n}")),
        }
    }

    /// Per-frame housekeeping: follow mode, and what has been seen.
    pub fn tick(&mut self) {
        if !self.background {
            // No scan thread: scan what the index gained here.
            self.scan.catch_up(&self.shared);
        }
        let len = self.len();
        if self.follow {
            if len > 0 {
                self.select(len - 1);
            }
            self.seen = len;
        } else {
            // The window may have shrunk since the last frame: keep the selected row on it.
            self.scroll_into_view();
            let shown = (self.top + self.list_rows.max(1)).min(len);
            self.seen = self.seen.max(shown).min(len);
        }
    }

    /// Visible detail-tree lines of the selected record (collapsed children left out).
    pub fn detail_lines(&self) -> Vec<Node> {
        let Some(n) = self.selected() else {
            return vec![];
        };
        let nodes = {
            let Ok(ix) = self.shared.index.read() else {
                return vec![];
            };
            tree(&ix, n)
        };
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

    /// The byte range of the frame highlighted in the hex pane (the selected tree line's).
    pub fn highlight(&self) -> Option<(usize, usize)> {
        if self.focus == Pane::List {
            return None;
        }
        self.detail_lines()
            .get(self.detail_sel)
            .and_then(|n| n.range)
    }

    /// Apply the filter text; on error keep the old filter and show the error.
    pub fn apply_filter(&mut self, text: &str) {
        match Filter::parse(text) {
            Ok(f) => {
                let keep = self.selected();
                self.filter_error = None;
                self.filter_text = if text.trim().is_empty() {
                    String::new()
                } else {
                    text.to_string()
                };
                let filter = (!self.filter_text.is_empty()).then_some(f);
                self.scan
                    .start(self.shared.clone(), filter, self.background);
                self.top = 0;
                self.sel = 0;
                // Another list: what was seen of the old one says nothing of it.
                self.seen = 0;
                if let Some(n) = keep {
                    if let Some(p) = self.position_of(n) {
                        self.select(p);
                    }
                }
            }
            Err(e) => {
                self.filter_error = Some(e);
            }
        }
    }

    /// Find the next (or previous) shown record matching the search expression; without one,
    /// the next record with a diagnostic.
    pub fn search_step(&mut self, forward: bool) {
        let len = self.len();
        if len == 0 {
            return;
        }
        let diag = Filter::parse("diag").ok();
        let f = match self.search.as_ref().map(|(_, f)| f.clone()).or(diag) {
            Some(f) => f,
            None => return,
        };
        let mut pos = self.sel;
        const CHUNK: usize = 4096;
        loop {
            let (from, ok) = if forward {
                (pos + 1, pos + 1 < len)
            } else {
                (pos.saturating_sub(CHUNK), pos > 0)
            };
            if !ok {
                self.message = Some("search: no more matches".into());
                return;
            }
            let count = if forward { CHUNK } else { pos - from };
            let ns = self.rows(from, count);
            let Ok(ix) = self.shared.index.read() else {
                return;
            };
            let hit = |n: &u64| fields::matches(&f, &ix, *n);
            let found = if forward {
                ns.iter().position(hit)
            } else {
                ns.iter().rposition(hit)
            };
            drop(ix);
            if let Some(i) = found {
                self.follow = false;
                self.select(from + i);
                self.message = None;
                return;
            }
            pos = if forward { from + ns.len() - 1 } else { from };
            if forward && ns.is_empty() {
                self.message = Some("search: no more matches".into());
                return;
            }
        }
    }

    /// Jump to the record paired with the selected one.
    pub fn jump_pair(&mut self) {
        let Some(n) = self.selected() else { return };
        let pair = self
            .shared
            .index
            .read()
            .ok()
            .and_then(|ix| ix.rec(n).map(|r| r.pair));
        match pair {
            Some(p) if p != 0 => self.goto(p as u64),
            _ => self.message = Some(format!("#{n} has no pair")),
        }
    }

    /// The display filter for the selected detail line (in the timeline: for the selected
    /// record's message), applied, prepared in the filter bar, or and-ed with the current one.
    pub fn selected_as_filter(&mut self, what: AsFilter) {
        let Some(n) = self.selected() else { return };
        let index = &self.shared.index;
        let expr = if self.focus == Pane::List {
            index
                .read()
                .ok()
                .and_then(|ix| as_filter::for_record(&ix, n))
        } else {
            let line = self.detail_lines().into_iter().nth(self.detail_sel);
            line.and_then(|node| {
                let ix = index.read().ok()?;
                as_filter::for_node(&ix, n, &node)
            })
        };
        let Some(expr) = expr else {
            self.message =
                Some("no filter for this line (pick a field, header or diagnostic)".into());
            return;
        };
        match what {
            AsFilter::Prepare => {
                self.filter_error = Filter::parse(&expr).err();
                self.input = Input::Filter(expr);
            }
            AsFilter::Apply | AsFilter::And => {
                let text = if what == AsFilter::And {
                    as_filter::and(&self.filter_text, &expr)
                } else {
                    expr
                };
                self.apply_filter(&text);
                self.message = Some(format!("filter: {text}"));
            }
        }
    }

    fn on_help_key(&mut self, k: KeyEvent) {
        let page = self.help_rows.max(1);
        match k.code {
            KeyCode::Char('q') | KeyCode::Char('?') | KeyCode::Esc | KeyCode::Enter => {
                self.help = false
            }
            KeyCode::Char('j') | KeyCode::Down => self.help_scroll += 1,
            KeyCode::Char('k') | KeyCode::Up => {
                self.help_scroll = self.help_scroll.saturating_sub(1)
            }
            KeyCode::PageDown | KeyCode::Char(' ') => self.help_scroll += page,
            KeyCode::PageUp => self.help_scroll = self.help_scroll.saturating_sub(page),
            KeyCode::Char('g') | KeyCode::Home => self.help_scroll = 0,
            // The view clamps it to the last page.
            KeyCode::Char('G') | KeyCode::End => self.help_scroll = usize::MAX / 2,
            _ => {}
        }
    }

    /// Handle a key.
    pub fn on_key(&mut self, k: KeyEvent) {
        if k.kind == ratatui::crossterm::event::KeyEventKind::Release {
            return;
        }
        let ctrl = k.modifiers.contains(KeyModifiers::CONTROL);
        if ctrl && matches!(k.code, KeyCode::Char('c') | KeyCode::Char('q')) {
            self.quit = true;
            return;
        }
        if self.input != Input::None {
            self.on_input_key(k);
            return;
        }
        if self.help {
            self.on_help_key(k);
            return;
        }
        self.message = None;
        match k.code {
            KeyCode::Char('q') => {
                if self.view == View::Timeline {
                    self.quit = true;
                } else {
                    self.view = View::Timeline;
                }
            }
            KeyCode::Esc => self.view = View::Timeline,
            KeyCode::Char('?') => {
                self.help = true;
                self.help_scroll = 0;
            }
            KeyCode::Char('/') => self.input = Input::Filter(self.filter_text.clone()),
            KeyCode::Char(':') => self.input = Input::Goto(String::new()),
            KeyCode::Char('s') => {
                self.input = Input::Search(
                    self.search
                        .as_ref()
                        .map(|s| s.0.clone())
                        .unwrap_or_default(),
                )
            }
            KeyCode::Char('n') => self.search_step(true),
            KeyCode::Char('N') => self.search_step(false),
            KeyCode::Char('p') => self.jump_pair(),
            KeyCode::Char('a') => self.selected_as_filter(AsFilter::Apply),
            KeyCode::Char('A') => self.selected_as_filter(AsFilter::Prepare),
            KeyCode::Char('&') => self.selected_as_filter(AsFilter::And),
            KeyCode::Char('>') => self.detail_left += 8,
            KeyCode::Char('<') => self.detail_left = self.detail_left.saturating_sub(8),
            KeyCode::Char('t') => {
                self.time_mode = match self.time_mode {
                    TimeMode::Relative => TimeMode::Delta,
                    TimeMode::Delta => TimeMode::Absolute,
                    TimeMode::Absolute => TimeMode::Relative,
                }
            }
            KeyCode::Char('F') | KeyCode::Char('f') => {
                self.follow = !self.follow;
                if !self.live {
                    self.message =
                        Some(format!("follow {}", if self.follow { "on" } else { "off" }));
                }
                self.tick();
            }
            KeyCode::Char('1') => self.view = View::Timeline,
            KeyCode::Char('2') | KeyCode::Char('S') => self.view = View::Stats,
            KeyCode::Char('3') | KeyCode::Char('P') => self.view = View::Plot,
            KeyCode::Tab => {
                self.focus = match self.focus {
                    Pane::List => Pane::Detail,
                    Pane::Detail => Pane::Hex,
                    Pane::Hex => Pane::List,
                }
            }
            KeyCode::BackTab => {
                self.focus = match self.focus {
                    Pane::List => Pane::Hex,
                    Pane::Detail => Pane::List,
                    Pane::Hex => Pane::Detail,
                }
            }
            _ => self.on_move_key(k),
        }
    }

    fn on_move_key(&mut self, k: KeyEvent) {
        let ctrl = k.modifiers.contains(KeyModifiers::CONTROL);
        let page = match self.focus {
            Pane::Detail => self.detail_rows.max(1),
            _ => self.list_rows.max(1),
        };
        #[derive(PartialEq)]
        enum M {
            By(isize),
            Top,
            Bottom,
            Toggle,
            Collapse,
            Expand,
            None,
        }
        let m = match k.code {
            KeyCode::Char('j') | KeyCode::Down => M::By(1),
            KeyCode::Char('k') | KeyCode::Up => M::By(-1),
            KeyCode::Char('d') if ctrl => M::By(page as isize / 2),
            KeyCode::Char('u') if ctrl => M::By(-(page as isize) / 2),
            KeyCode::Char('f') if ctrl => M::By(page as isize),
            KeyCode::Char('b') if ctrl => M::By(-(page as isize)),
            KeyCode::PageDown | KeyCode::Char(' ') if self.focus != Pane::Detail => {
                M::By(page as isize)
            }
            KeyCode::PageDown => M::By(page as isize),
            KeyCode::PageUp => M::By(-(page as isize)),
            KeyCode::Char('g') | KeyCode::Home => M::Top,
            KeyCode::Char('G') | KeyCode::End => M::Bottom,
            KeyCode::Enter | KeyCode::Char(' ') => M::Toggle,
            KeyCode::Char('h') | KeyCode::Left => M::Collapse,
            KeyCode::Char('l') | KeyCode::Right => M::Expand,
            _ => M::None,
        };
        match self.view {
            View::Stats => {
                self.stats_scroll = match m {
                    M::By(d) => self.stats_scroll.saturating_add_signed(d),
                    M::Top => 0,
                    M::Bottom => usize::MAX / 2,
                    _ => self.stats_scroll,
                };
                return;
            }
            View::Plot => {
                match m {
                    M::By(d) if d > 0 => self.plot_page += 1,
                    M::By(_) => self.plot_page = self.plot_page.saturating_sub(1),
                    M::Top => self.plot_page = 0,
                    _ => {}
                }
                return;
            }
            View::Timeline => {}
        }
        match self.focus {
            Pane::List => match m {
                M::By(d) => {
                    self.follow = false;
                    self.select(self.sel.saturating_add_signed(d));
                }
                M::Top => {
                    self.follow = false;
                    self.select(0);
                }
                M::Bottom => {
                    // At the end of a live capture: follow it again (as `tail -f`).
                    if self.live {
                        self.follow = true;
                    }
                    self.select(self.len().saturating_sub(1));
                }
                M::Toggle => self.focus = Pane::Detail,
                _ => {}
            },
            Pane::Detail => {
                let lines = self.detail_lines();
                let last = lines.len().saturating_sub(1);
                match m {
                    M::By(d) => {
                        self.detail_sel = self.detail_sel.saturating_add_signed(d).min(last)
                    }
                    M::Top => self.detail_sel = 0,
                    M::Bottom => self.detail_sel = last,
                    M::Toggle | M::Collapse | M::Expand => {
                        if let Some(node) = lines.get(self.detail_sel) {
                            let id = node.id.clone();
                            if m == M::Toggle && node.link.is_some() {
                                self.jump_pair();
                                return;
                            }
                            let collapsed = self.collapsed.contains(&id);
                            match m {
                                M::Toggle if collapsed => {
                                    self.collapsed.remove(&id);
                                }
                                M::Toggle | M::Collapse => {
                                    self.collapsed.insert(id);
                                }
                                _ => {
                                    self.collapsed.remove(&id);
                                }
                            }
                        }
                    }
                    M::None => {}
                }
                let h = self.detail_rows.max(1);
                if self.detail_sel < self.detail_top {
                    self.detail_top = self.detail_sel;
                } else if self.detail_sel >= self.detail_top + h {
                    self.detail_top = self.detail_sel + 1 - h;
                }
            }
            Pane::Hex => match m {
                M::By(d) => self.hex_top = self.hex_top.saturating_add_signed(d.signum()),
                M::Top => self.hex_top = 0,
                _ => {}
            },
        }
    }

    fn on_input_key(&mut self, k: KeyEvent) {
        let text = match &mut self.input {
            Input::Filter(s) | Input::Goto(s) | Input::Search(s) => s,
            Input::None => return,
        };
        match k.code {
            KeyCode::Esc => {
                self.input = Input::None;
                self.filter_error = None;
            }
            KeyCode::Backspace => {
                text.pop();
            }
            KeyCode::Char('u') if k.modifiers.contains(KeyModifiers::CONTROL) => text.clear(),
            KeyCode::Char(c) => text.push(c),
            KeyCode::Enter => {
                let input = std::mem::replace(&mut self.input, Input::None);
                match input {
                    Input::Filter(s) => {
                        self.apply_filter(&s);
                        if self.filter_error.is_some() {
                            self.input = Input::Filter(s);
                        }
                    }
                    Input::Goto(s) => match s.trim().trim_start_matches('#').parse::<u64>() {
                        Ok(n) => self.goto(n),
                        Err(_) => self.message = Some(format!("not a record number: {s:?}")),
                    },
                    Input::Search(s) => {
                        if s.trim().is_empty() {
                            self.search = None;
                        } else {
                            match Filter::parse(&s) {
                                Ok(f) => {
                                    self.search = Some((s, f));
                                    self.search_step(true);
                                }
                                Err(e) => {
                                    self.message = Some(format!("search: {e}"));
                                }
                            }
                        }
                    }
                    Input::None => {}
                }
                return;
            }
            _ => {}
        }
        // Live feedback on the filter being typed.
        if let Input::Filter(s) = &self.input {
            self.filter_error = Filter::parse(s).err();
        }
    }

    /// Handle a mouse event (wheel scrolls the pane under the pointer; a click selects).
    pub fn on_mouse(&mut self, m: MouseEvent) {
        let at = Position::new(m.column, m.row);
        let pane = if self.areas.list.contains(at) {
            Some(Pane::List)
        } else if self.areas.detail.contains(at) {
            Some(Pane::Detail)
        } else if self.areas.hex.contains(at) {
            Some(Pane::Hex)
        } else {
            None
        };
        let key = |c| KeyEvent::new(c, KeyModifiers::NONE);
        if self.help {
            match m.kind {
                MouseEventKind::ScrollDown => self.help_scroll += 3,
                MouseEventKind::ScrollUp => self.help_scroll = self.help_scroll.saturating_sub(3),
                _ => {}
            }
            return;
        }
        match m.kind {
            MouseEventKind::ScrollDown | MouseEventKind::ScrollUp => {
                if self.view != View::Timeline {
                    self.on_move_key(key(if m.kind == MouseEventKind::ScrollDown {
                        KeyCode::Down
                    } else {
                        KeyCode::Up
                    }));
                    return;
                }
                if let Some(p) = pane {
                    let old = self.focus;
                    self.focus = p;
                    for _ in 0..3 {
                        self.on_move_key(key(if m.kind == MouseEventKind::ScrollDown {
                            KeyCode::Down
                        } else {
                            KeyCode::Up
                        }));
                    }
                    self.focus = old;
                }
            }
            MouseEventKind::ScrollLeft if pane == Some(Pane::Detail) => {
                self.detail_left = self.detail_left.saturating_sub(8)
            }
            MouseEventKind::ScrollRight if pane == Some(Pane::Detail) => self.detail_left += 8,
            MouseEventKind::Down(MouseButton::Left) => match pane {
                Some(Pane::List) => {
                    self.focus = Pane::List;
                    let row = (m.row - self.areas.list.y) as usize;
                    self.follow = false;
                    self.select(self.top + row);
                }
                Some(Pane::Detail) => {
                    self.focus = Pane::Detail;
                    let row = (m.row - self.areas.detail.y) as usize;
                    let last = self.detail_lines().len().saturating_sub(1);
                    self.detail_sel = (self.detail_top + row).min(last);
                }
                Some(Pane::Hex) => self.focus = Pane::Hex,
                None => {}
            },
            _ => {}
        }
    }
}
