//! Application state and event handling (no terminal needed): keys (looked up in the one key
//! list, [`crate::keys`]) and mouse events change the state of the parts
//! ([`crate::components`]); [`App::update`] fits it to the screen before each frame and
//! [`crate::ui::draw`] renders it.

use crate::as_filter;
use crate::components::detail::Detail;
use crate::components::filter_bar::FilterBar;
use crate::components::help::Help;
use crate::components::hex::Hex;
use crate::components::plot::Plot;
use crate::components::stats::{self, Stats};
use crate::components::timeline::Timeline;
use crate::components::Step;
use crate::decode::{tree, Node};
use crate::fields;
use crate::index::Shared;
use crate::keys::{self, Action, Ctx, Move};
use crate::scan::Scan;
use crate::ui::Screen;
use aptscope_dissector::filter::{Filter, FilterError};
use ratatui::crossterm::event::{KeyEvent, KeyEventKind, MouseButton, MouseEvent, MouseEventKind};
use ratatui::layout::{Position, Rect};
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

/// Screen areas of the timeline's panes at the last update, for mouse events.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Areas {
    /// Timeline rows (inside the border).
    pub list: Rect,
    /// Detail rows.
    pub detail: Rect,
    /// Hex rows.
    pub hex: Rect,
}

/// The whole UI state: the parts ([`crate::components`]) and what they share.
pub struct App {
    /// The capture index.
    shared: Arc<Shared>,
    /// The filter/statistics scan.
    scan: Arc<Scan>,
    /// Scans run in background threads (false in tests: synchronous).
    background: bool,
    /// Screen.
    view: View,
    /// Focused pane.
    focus: Pane,
    /// The source is live: the status bar shows LIVE (following) or PAUSED with the count of
    /// records not yet seen.
    live: bool,
    /// Quit requested.
    quit: bool,
    /// File name, for the title.
    title: String,
    /// Screen areas of the timeline's panes at the last update.
    areas: Areas,
    timeline: Timeline,
    detail: Detail,
    hex: Hex,
    bar: FilterBar,
    stats: Stats,
    plot: Plot,
    help: Help,
}

impl App {
    /// A new UI over an index (being built or complete); `background`: scans run in threads
    /// of their own (false: synchronously, as tests want).
    pub fn new(shared: Arc<Shared>, title: &str, background: bool) -> Self {
        let scan = Arc::new(Scan::default());
        let app = App {
            shared,
            scan,
            background,
            view: View::Timeline,
            focus: Pane::List,
            live: false,
            quit: false,
            title: title.to_string(),
            areas: Areas::default(),
            timeline: Timeline::default(),
            detail: Detail::default(),
            hex: Hex::default(),
            bar: FilterBar::default(),
            stats: Stats::default(),
            plot: Plot::default(),
            help: Help::default(),
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
            self.timeline.follow = true;
        }
    }

    /// The capture index.
    pub fn shared(&self) -> &Arc<Shared> {
        &self.shared
    }

    /// The filter/statistics scan.
    pub fn scan(&self) -> &Arc<Scan> {
        &self.scan
    }

    /// The source's name, as the title shows it.
    pub fn title(&self) -> &str {
        &self.title
    }

    /// Which screen is shown.
    pub fn view(&self) -> View {
        self.view
    }

    /// Which pane of the timeline view has the focus.
    pub fn focus(&self) -> Pane {
        self.focus
    }

    /// Give `pane` the focus (as Tab or a click does).
    pub fn set_focus(&mut self, pane: Pane) {
        self.focus = pane;
    }

    /// The line being edited at the bottom of the screen.
    pub fn input(&self) -> &Input {
        &self.bar.input
    }

    /// The applied display filter (empty: none).
    pub fn filter_text(&self) -> &str {
        &self.bar.filter_text
    }

    /// The error of the filter being typed, if any.
    pub fn filter_error(&self) -> Option<&FilterError> {
        self.bar.filter_error.as_ref()
    }

    /// The status bar's message, if any.
    pub fn message(&self) -> Option<&str> {
        self.bar.message.as_deref()
    }

    /// How times are shown.
    pub fn time_mode(&self) -> TimeMode {
        self.timeline.time_mode
    }

    /// Whether the user asked to quit.
    pub fn should_quit(&self) -> bool {
        self.quit
    }

    /// Whether the help overlay is shown.
    pub fn help_shown(&self) -> bool {
        self.help.shown
    }

    /// Show or hide the help overlay (where it was scrolled to).
    pub fn set_help(&mut self, shown: bool) {
        self.help.shown = shown;
    }

    /// First shown line of the help overlay.
    pub fn help_scroll(&self) -> usize {
        self.help.scroll
    }

    /// Position of the selected row in the shown list.
    pub fn position(&self) -> usize {
        self.timeline.sel
    }

    /// Position of the first row on screen.
    pub fn top(&self) -> usize {
        self.timeline.top
    }

    /// Rows of the timeline on screen (as of the last [`App::update`]).
    pub fn rows_on_screen(&self) -> usize {
        self.timeline.rows
    }

    /// Whether the selection follows new records.
    pub fn following(&self) -> bool {
        self.timeline.follow
    }

    /// Whether the source is live.
    pub fn live(&self) -> bool {
        self.live
    }

    /// The selected line of the detail tree (among visible lines).
    pub fn detail_selected(&self) -> usize {
        self.detail.sel
    }

    /// Select line `i` of the detail tree (among visible lines).
    pub fn select_detail(&mut self, i: usize) {
        self.detail.sel = i;
    }

    /// Columns the detail tree is scrolled to the right.
    pub fn detail_left(&self) -> usize {
        self.detail.left
    }

    /// The detail tree's state.
    pub(crate) fn detail(&self) -> &Detail {
        &self.detail
    }

    /// Screen areas of the timeline's panes at the last update (for mouse events).
    pub fn areas(&self) -> Areas {
        self.areas
    }

    /// Rows of the shown list not seen yet (arrived below the screen while paused).
    pub fn unseen(&self) -> usize {
        self.len().saturating_sub(self.timeline.seen)
    }

    /// Number of rows in the shown list (all records, or those the filter matches).
    pub fn len(&self) -> usize {
        if self.bar.filter_text.is_empty() {
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
        if self.bar.filter_text.is_empty() {
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
        self.rows(self.timeline.sel, 1).first().copied()
    }

    /// Position of record `n` in the shown list (or of the first shown record after it).
    fn position_of(&self, n: u64) -> Option<usize> {
        if self.bar.filter_text.is_empty() {
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
        if new != self.timeline.sel {
            self.detail.reset();
            self.hex.top = 0;
        }
        self.timeline.sel = new;
        self.timeline.scroll_into_view();
    }

    /// Go to record `n` (or the next shown one).
    pub fn goto(&mut self, n: u64) {
        match self.position_of(n) {
            Some(p) => {
                self.timeline.follow = false;
                self.select(p);
                if self.selected() != Some(n) {
                    self.bar.message =
                        Some(format!("#{n} is not shown; nearest after it selected"));
                }
            }
            None => self.bar.message = Some(format!("no record #{n}")),
        }
    }

    /// Per-frame housekeeping: follow mode, and what has been seen.
    pub fn tick(&mut self) {
        if !self.background {
            // No scan thread: scan what the index gained here.
            self.scan.catch_up(&self.shared);
        }
        let len = self.len();
        if self.timeline.follow {
            if len > 0 {
                self.select(len - 1);
            }
            self.timeline.seen = len;
        } else {
            // The window may have shrunk since the last frame: keep the selected row on it.
            let t = &mut self.timeline;
            t.scroll_into_view();
            let shown = (t.top + t.rows.max(1)).min(len);
            t.seen = t.seen.max(shown).min(len);
        }
    }

    /// Before drawing on a screen `area`: the parts learn their sizes and keep their scrolls
    /// in range; the timeline view also does its per-frame housekeeping ([`App::tick`]).
    /// [`crate::ui::draw`] calls it; drawing then only reads the state.
    pub fn update(&mut self, area: Rect) {
        let screen = Screen::of(area, self.bar.height());
        match self.view {
            View::Timeline => {
                // Below the border line (and, for the timeline, the column headers).
                let below = |r: Rect, n: u16| Rect {
                    y: r.y + n.min(r.height),
                    height: r.height.saturating_sub(n),
                    ..r
                };
                self.areas = Areas {
                    list: below(screen.list, 2),
                    detail: below(screen.detail, 1),
                    hex: below(screen.hex, 1),
                };
                self.timeline.rows = self.areas.list.height as usize;
                self.detail.rows = self.areas.detail.height as usize;
                self.tick();
                let lines = self.detail_lines();
                self.detail.update(lines, screen.detail.width as usize);
            }
            View::Stats => {
                let text = stats::text(self);
                self.stats.update(text, screen.body);
            }
            View::Plot => {
                let series = self.shared.index.read().map_or(0, |ix| ix.series.len());
                self.plot.update(series);
            }
        }
        if self.help.shown {
            self.help.update(area);
        }
    }

    /// The parts, for drawing.
    pub(crate) fn parts(&self) -> Parts<'_> {
        Parts {
            timeline: &self.timeline,
            detail: &self.detail,
            hex: &self.hex,
            bar: &self.bar,
            stats: &self.stats,
            plot: &self.plot,
            help: &self.help,
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
        self.detail.visible(&nodes)
    }

    /// The byte range of the frame highlighted in the hex pane (the selected tree line's).
    pub fn highlight(&self) -> Option<(usize, usize)> {
        if self.focus == Pane::List {
            return None;
        }
        self.detail_lines()
            .get(self.detail.sel)
            .and_then(|n| n.range)
    }

    /// Apply the filter text; on error keep the old filter and show the error.
    pub fn apply_filter(&mut self, text: &str) {
        match Filter::parse(text) {
            Ok(f) => {
                let keep = self.selected();
                self.bar.filter_error = None;
                self.bar.filter_text = if text.trim().is_empty() {
                    String::new()
                } else {
                    text.to_string()
                };
                let filter = (!self.bar.filter_text.is_empty()).then_some(f);
                self.scan
                    .start(self.shared.clone(), filter, self.background);
                self.timeline.top = 0;
                self.timeline.sel = 0;
                // Another list: what was seen of the old one says nothing of it.
                self.timeline.seen = 0;
                if let Some(n) = keep {
                    if let Some(p) = self.position_of(n) {
                        self.select(p);
                    }
                }
            }
            Err(e) => {
                self.bar.filter_error = Some(e);
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
        let f = match self.bar.search.as_ref().map(|(_, f)| f.clone()).or(diag) {
            Some(f) => f,
            None => return,
        };
        let mut pos = self.timeline.sel;
        const CHUNK: usize = 4096;
        loop {
            let (from, ok) = if forward {
                (pos + 1, pos + 1 < len)
            } else {
                (pos.saturating_sub(CHUNK), pos > 0)
            };
            if !ok {
                self.bar.message = Some("search: no more matches".into());
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
                self.timeline.follow = false;
                self.select(from + i);
                self.bar.message = None;
                return;
            }
            pos = if forward { from + ns.len() - 1 } else { from };
            if forward && ns.is_empty() {
                self.bar.message = Some("search: no more matches".into());
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
            _ => self.bar.message = Some(format!("#{n} has no pair")),
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
            let line = self.detail_lines().into_iter().nth(self.detail.sel);
            line.and_then(|node| {
                let ix = index.read().ok()?;
                as_filter::for_node(&ix, n, &node)
            })
        };
        let Some(expr) = expr else {
            self.bar.message =
                Some("no filter for this line (pick a field, header or diagnostic)".into());
            return;
        };
        match what {
            AsFilter::Prepare => {
                self.bar.filter_error = Filter::parse(&expr).err();
                self.bar.input = Input::Filter(expr);
            }
            AsFilter::Apply | AsFilter::And => {
                let text = if what == AsFilter::And {
                    as_filter::and(&self.bar.filter_text, &expr)
                } else {
                    expr
                };
                self.apply_filter(&text);
                self.bar.message = Some(format!("filter: {text}"));
            }
        }
    }

    /// Handle a key: what the key list ([`keys::KEYS`]) says it does where it was pressed.
    pub fn on_key(&mut self, k: KeyEvent) {
        if k.kind == KeyEventKind::Release {
            return;
        }
        if let Some(a) = keys::action(Ctx::Always, &k) {
            self.act(a);
            return;
        }
        if self.bar.input != Input::None {
            self.on_input_key(k);
            return;
        }
        if self.help.shown {
            if let Some(a) = keys::action(Ctx::Help, &k) {
                self.help.on_action(a);
            }
            return;
        }
        self.bar.message = None;
        match keys::action(Ctx::Main, &k) {
            Some(a) => self.act(a),
            None => self.on_move(None),
        }
    }

    /// Do what a key of the views and panes does.
    fn act(&mut self, a: Action) {
        match a {
            Action::Quit => self.quit = true,
            Action::QuitOrBack => {
                if self.view == View::Timeline {
                    self.quit = true;
                } else {
                    self.view = View::Timeline;
                }
            }
            Action::Timeline => self.view = View::Timeline,
            Action::Stats => self.view = View::Stats,
            Action::Plot => self.view = View::Plot,
            Action::Help => self.help.open(),
            Action::CloseHelp => self.help.shown = false,
            Action::EditFilter => self.bar.input = Input::Filter(self.bar.filter_text.clone()),
            Action::Goto => self.bar.input = Input::Goto(String::new()),
            Action::EditSearch => {
                self.bar.input = Input::Search(
                    self.bar
                        .search
                        .as_ref()
                        .map(|s| s.0.clone())
                        .unwrap_or_default(),
                )
            }
            Action::SearchNext => self.search_step(true),
            Action::SearchPrev => self.search_step(false),
            Action::JumpPair => self.jump_pair(),
            Action::AsFilter(what) => self.selected_as_filter(what),
            Action::ScrollRight => self.detail.left += 8,
            Action::ScrollLeft => self.detail.left = self.detail.left.saturating_sub(8),
            Action::CycleTime => self.timeline.cycle_time(),
            Action::ToggleFollow => {
                let t = &mut self.timeline;
                t.follow = !t.follow;
                if !self.live {
                    self.bar.message =
                        Some(format!("follow {}", if t.follow { "on" } else { "off" }));
                }
                self.tick();
            }
            Action::NextPane => {
                self.focus = match self.focus {
                    Pane::List => Pane::Detail,
                    Pane::Detail => Pane::Hex,
                    Pane::Hex => Pane::List,
                }
            }
            Action::PrevPane => {
                self.focus = match self.focus {
                    Pane::List => Pane::Hex,
                    Pane::Detail => Pane::List,
                    Pane::Hex => Pane::Detail,
                }
            }
            Action::Move(m) => self.on_move(Some(m)),
            // The input line's keys: handled there.
            Action::Cancel | Action::Commit | Action::DeleteChar | Action::ClearLine => {}
        }
    }

    /// A movement in the view or pane that has the focus (`None`: a key that does nothing,
    /// but the detail tree still scrolls its selection into view).
    fn on_move(&mut self, m: Option<Move>) {
        let page = match self.focus {
            Pane::Detail => self.detail.rows.max(1),
            _ => self.timeline.rows.max(1),
        } as isize;
        let step = match m {
            None => Step::None,
            Some(Move::Down) => Step::By(1),
            Some(Move::Up) => Step::By(-1),
            Some(Move::HalfDown) => Step::By(page / 2),
            Some(Move::HalfUp) => Step::By(-page / 2),
            Some(Move::PageDown) => Step::By(page),
            Some(Move::PageUp) => Step::By(-page),
            Some(Move::PageOrOpen) if self.focus != Pane::Detail => Step::By(page),
            Some(Move::Open | Move::PageOrOpen) => Step::Toggle,
            Some(Move::Top) => Step::Top,
            Some(Move::Bottom) => Step::Bottom,
            Some(Move::Collapse) => Step::Collapse,
            Some(Move::Expand) => Step::Expand,
        };
        match (self.view, self.focus) {
            (View::Stats, _) => self.stats.on_step(step),
            (View::Plot, _) => self.plot.on_step(step),
            (View::Timeline, Pane::List) => match step {
                Step::By(d) => {
                    self.timeline.follow = false;
                    self.select(self.timeline.sel.saturating_add_signed(d));
                }
                Step::Top => {
                    self.timeline.follow = false;
                    self.select(0);
                }
                Step::Bottom => {
                    // At the end of a live capture: follow it again (as `tail -f`).
                    if self.live {
                        self.timeline.follow = true;
                    }
                    self.select(self.len().saturating_sub(1));
                }
                Step::Toggle => self.focus = Pane::Detail,
                _ => {}
            },
            (View::Timeline, Pane::Detail) => {
                let lines = self.detail_lines();
                if self.detail.on_step(step, &lines) {
                    self.jump_pair();
                }
            }
            (View::Timeline, Pane::Hex) => self.hex.on_step(step),
        }
    }

    fn on_input_key(&mut self, k: KeyEvent) {
        if self.bar.edit(keys::action(Ctx::Input, &k), k.code) {
            self.commit_input();
        }
    }

    /// Enter on the input line: apply the filter, go to the record or search.
    fn commit_input(&mut self) {
        let input = std::mem::replace(&mut self.bar.input, Input::None);
        match input {
            Input::Filter(s) => {
                self.apply_filter(&s);
                if self.bar.filter_error.is_some() {
                    self.bar.input = Input::Filter(s);
                }
            }
            Input::Goto(s) => match s.trim().trim_start_matches('#').parse::<u64>() {
                Ok(n) => self.goto(n),
                Err(_) => self.bar.message = Some(format!("not a record number: {s:?}")),
            },
            Input::Search(s) => {
                if s.trim().is_empty() {
                    self.bar.search = None;
                } else {
                    match Filter::parse(&s) {
                        Ok(f) => {
                            self.bar.search = Some((s, f));
                            self.search_step(true);
                        }
                        Err(e) => {
                            self.bar.message = Some(format!("search: {e}"));
                        }
                    }
                }
            }
            Input::None => {}
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
        if self.help.shown {
            match m.kind {
                MouseEventKind::ScrollDown => self.help.scroll_by(3),
                MouseEventKind::ScrollUp => self.help.scroll_by(-3),
                _ => {}
            }
            return;
        }
        match m.kind {
            MouseEventKind::ScrollDown | MouseEventKind::ScrollUp => {
                let way = if m.kind == MouseEventKind::ScrollDown {
                    Move::Down
                } else {
                    Move::Up
                };
                if self.view != View::Timeline {
                    self.on_move(Some(way));
                    return;
                }
                if let Some(p) = pane {
                    let old = self.focus;
                    self.focus = p;
                    for _ in 0..3 {
                        self.on_move(Some(way));
                    }
                    self.focus = old;
                }
            }
            MouseEventKind::ScrollLeft if pane == Some(Pane::Detail) => {
                self.detail.left = self.detail.left.saturating_sub(8)
            }
            MouseEventKind::ScrollRight if pane == Some(Pane::Detail) => self.detail.left += 8,
            MouseEventKind::Down(MouseButton::Left) => match pane {
                Some(Pane::List) => {
                    self.focus = Pane::List;
                    let row = (m.row - self.areas.list.y) as usize;
                    self.timeline.follow = false;
                    self.select(self.timeline.top + row);
                }
                Some(Pane::Detail) => {
                    self.focus = Pane::Detail;
                    let row = (m.row - self.areas.detail.y) as usize;
                    let last = self.detail_lines().len().saturating_sub(1);
                    self.detail.sel = (self.detail.top + row).min(last);
                }
                Some(Pane::Hex) => self.focus = Pane::Hex,
                None => {}
            },
            _ => {}
        }
    }
}

/// The parts of the UI, read-only, for drawing.
pub(crate) struct Parts<'a> {
    pub(crate) timeline: &'a Timeline,
    pub(crate) detail: &'a Detail,
    pub(crate) hex: &'a Hex,
    pub(crate) bar: &'a FilterBar,
    pub(crate) stats: &'a Stats,
    pub(crate) plot: &'a Plot,
    pub(crate) help: &'a Help,
}
