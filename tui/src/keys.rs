//! The one list of the viewer's keys: [`KEYS`] drives key handling ([`action`]), the help
//! overlay ([`help_rows`]) and the status bar's hints ([`hints`]), so the three cannot drift
//! apart (gitui's `keys/key_list.rs` is the model).

use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

/// A key as the list names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Key {
    /// This key, whatever the modifiers (`G` comes with Shift; `^s` still opens the search).
    Any(KeyCode),
    /// This character with Control held.
    Ctrl(char),
}

impl Key {
    /// Whether the key event is this key.
    pub fn matches(self, k: &KeyEvent) -> bool {
        match self {
            Key::Any(code) => k.code == code,
            Key::Ctrl(c) => {
                k.code == KeyCode::Char(c) && k.modifiers.contains(KeyModifiers::CONTROL)
            }
        }
    }

    /// The key's name in the help overlay.
    pub fn name(self) -> String {
        match self {
            Key::Ctrl(c) => format!("^{c}"),
            Key::Any(code) => match code {
                KeyCode::Char(' ') => "space".into(),
                KeyCode::Char(c) => c.to_string(),
                KeyCode::Up => "↑".into(),
                KeyCode::Down => "↓".into(),
                KeyCode::Left => "←".into(),
                KeyCode::Right => "→".into(),
                KeyCode::PageUp => "PgUp".into(),
                KeyCode::PageDown => "PgDn".into(),
                KeyCode::BackTab => "S-Tab".into(),
                KeyCode::Tab => "Tab".into(),
                KeyCode::Home => "Home".into(),
                KeyCode::End => "End".into(),
                KeyCode::Enter => "Enter".into(),
                KeyCode::Esc => "Esc".into(),
                KeyCode::Backspace => "Backspace".into(),
                other => format!("{other:?}"),
            },
        }
    }
}

/// A movement, applied by the pane or view that has the focus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Move {
    /// One line down.
    Down,
    /// One line up.
    Up,
    /// Half a page down.
    HalfDown,
    /// Half a page up.
    HalfUp,
    /// A page down.
    PageDown,
    /// A page up.
    PageUp,
    /// The first line.
    Top,
    /// The last line.
    Bottom,
    /// Open the selected line (detail: collapse / expand, or follow its link).
    Open,
    /// A page down, except in the detail tree, where it opens the line (space).
    PageOrOpen,
    /// Collapse the selected node.
    Collapse,
    /// Expand the selected node.
    Expand,
}

/// What a key does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Quit the viewer, whatever is open.
    Quit,
    /// Quit from the timeline; back to it from another view.
    QuitOrBack,
    /// Back to the timeline.
    Timeline,
    /// Open the help overlay.
    Help,
    /// Close the help overlay.
    CloseHelp,
    /// Edit the display filter.
    EditFilter,
    /// Type a record number to go to.
    Goto,
    /// Edit the search expression.
    EditSearch,
    /// The next search match.
    SearchNext,
    /// The previous search match.
    SearchPrev,
    /// Jump to the paired request / reply.
    JumpPair,
    /// The selected line as a display filter.
    AsFilter(crate::app::AsFilter),
    /// Scroll the detail tree right.
    ScrollRight,
    /// Scroll the detail tree left.
    ScrollLeft,
    /// Relative / delta / absolute times.
    CycleTime,
    /// Follow new records on / off.
    ToggleFollow,
    /// The statistics view.
    Stats,
    /// The plot view.
    Plot,
    /// The next pane.
    NextPane,
    /// The previous pane.
    PrevPane,
    /// A movement.
    Move(Move),
    /// Input line: cancel.
    Cancel,
    /// Input line: apply.
    Commit,
    /// Input line: delete the last character.
    DeleteChar,
    /// Input line: clear it.
    ClearLine,
}

/// Where a binding applies.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ctx {
    /// Everywhere, before anything else.
    Always,
    /// While a line is being edited (filter, search, go to).
    Input,
    /// While the help overlay is open.
    Help,
    /// The views and panes.
    Main,
}

/// How the help overlay's key column names a binding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shown {
    /// By the key's name ([`Key::name`]).
    Name,
    /// Not at all (a synonym).
    Hidden,
    /// As this text.
    As(&'static str),
}

/// A key and what it does.
#[derive(Debug, Clone, Copy)]
pub struct Bind {
    /// The key.
    pub key: Key,
    /// What it does.
    pub action: Action,
    /// How the help overlay names it.
    pub shown: Shown,
}

/// One line of the list: keys, the help overlay's text and the status bar's hints.
#[derive(Debug, Clone, Copy)]
pub struct Entry {
    /// Where the keys apply.
    pub ctx: Ctx,
    /// The keys, in the order the help names them.
    pub binds: &'static [Bind],
    /// The help overlay's key column when it is not the keys' names (the mouse).
    pub label: Option<&'static str>,
    /// The help overlay's text; `None`: not listed there.
    pub help: Option<&'static str>,
    /// Status bar hints, with their rank (as many as fit are shown, lowest rank first).
    pub hints: &'static [(u8, &'static str)],
}

const fn b(key: Key, action: Action) -> Bind {
    Bind {
        key,
        action,
        shown: Shown::Name,
    }
}

/// A binding the help overlay does not name (a synonym).
const fn hidden(key: Key, action: Action) -> Bind {
    Bind {
        key,
        action,
        shown: Shown::Hidden,
    }
}

const fn c(ch: char) -> Key {
    Key::Any(KeyCode::Char(ch))
}

const fn k(code: KeyCode) -> Key {
    Key::Any(code)
}

const fn main(binds: &'static [Bind], help: &'static str) -> Entry {
    Entry {
        ctx: Ctx::Main,
        binds,
        label: None,
        help: Some(help),
        hints: &[],
    }
}

const fn hinted(mut e: Entry, hints: &'static [(u8, &'static str)]) -> Entry {
    e.hints = hints;
    e
}

const fn unlisted(ctx: Ctx, binds: &'static [Bind]) -> Entry {
    Entry {
        ctx,
        binds,
        label: None,
        help: None,
        hints: &[],
    }
}

use crate::app::AsFilter as F;
use Action as A;
use KeyCode as K;
use Move as M;

/// Every key of the viewer. Within a context the first binding that matches wins; the help
/// overlay lists the entries that have help text, in this order.
pub const KEYS: &[Entry] = &[
    unlisted(
        Ctx::Always,
        &[b(Key::Ctrl('c'), A::Quit), b(Key::Ctrl('q'), A::Quit)],
    ),
    main(
        &[
            b(c('j'), A::Move(M::Down)),
            b(c('k'), A::Move(M::Up)),
            b(k(K::Up), A::Move(M::Up)),
            b(k(K::Down), A::Move(M::Down)),
        ],
        "move (in the focused pane)",
    ),
    main(
        &[
            b(c('g'), A::Move(M::Top)),
            b(c('G'), A::Move(M::Bottom)),
            b(k(K::Home), A::Move(M::Top)),
            b(k(K::End), A::Move(M::Bottom)),
        ],
        "first / last",
    ),
    main(
        &[
            b(k(K::PageUp), A::Move(M::PageUp)),
            b(k(K::PageDown), A::Move(M::PageDown)),
            b(Key::Ctrl('u'), A::Move(M::HalfUp)),
            b(Key::Ctrl('d'), A::Move(M::HalfDown)),
            hidden(Key::Ctrl('b'), A::Move(M::PageUp)),
        ],
        "page / half page",
    ),
    hinted(
        main(
            &[b(k(K::Tab), A::NextPane), b(k(K::BackTab), A::PrevPane)],
            "next / previous pane",
        ),
        &[(8, "Tab:pane")],
    ),
    main(
        &[
            b(k(K::Enter), A::Move(M::Open)),
            b(c(' '), A::Move(M::PageOrOpen)),
            b(c('h'), A::Move(M::Collapse)),
            b(c('l'), A::Move(M::Expand)),
            hidden(k(K::Left), A::Move(M::Collapse)),
            hidden(k(K::Right), A::Move(M::Expand)),
        ],
        "detail: collapse / expand; pair line: jump",
    ),
    main(
        &[b(c('<'), A::ScrollLeft), b(c('>'), A::ScrollRight)],
        "detail: scroll long lines left / right",
    ),
    hinted(
        main(
            &[b(c('a'), A::AsFilter(F::Apply))],
            "apply the selected detail line as a display filter (in the timeline: its message)",
        ),
        &[(5, "a,A:as filter")],
    ),
    main(
        &[b(c('A'), A::AsFilter(F::Prepare))],
        "prepare it as a filter: edit it in the filter bar, Enter applies",
    ),
    main(
        &[b(c('&'), A::AsFilter(F::And))],
        "apply the current filter narrowed by the selected line",
    ),
    hinted(
        main(
            &[b(c('/'), A::EditFilter)],
            "display filter (Enter apply, Esc cancel)",
        ),
        &[(1, "/:filter")],
    ),
    hinted(
        main(
            &[b(c('s'), A::EditSearch)],
            "search expression (filter language)",
        ),
        &[(6, "s,n,N:search")],
    ),
    main(
        &[b(c('n'), A::SearchNext), b(c('N'), A::SearchPrev)],
        "next / previous match (no search: diagnostics)",
    ),
    hinted(
        main(
            &[b(c('p'), A::JumpPair)],
            "jump to the paired request / reply",
        ),
        &[(7, "p:pair")],
    ),
    hinted(
        main(&[b(c(':'), A::Goto)], "go to record number"),
        &[(9, "::goto")],
    ),
    hinted(
        main(
            &[b(c('t'), A::CycleTime)],
            "time: relative / delta / absolute",
        ),
        &[(10, "t:time")],
    ),
    main(
        &[b(c('f'), A::ToggleFollow), hidden(c('F'), A::ToggleFollow)],
        "follow new records on/off (live: LIVE / PAUSED in the status bar; G resumes)",
    ),
    hinted(
        main(
            &[
                b(c('1'), A::Timeline),
                b(c('2'), A::Stats),
                b(c('3'), A::Plot),
                hidden(c('S'), A::Stats),
                hidden(c('P'), A::Plot),
            ],
            "timeline / statistics / plot",
        ),
        &[(2, "2:stats"), (3, "3:plot")],
    ),
    Entry {
        ctx: Ctx::Main,
        binds: &[],
        label: Some("mouse"),
        help: Some("wheel scrolls, click selects"),
        hints: &[],
    },
    hinted(
        main(
            &[
                b(c('?'), A::Help),
                b(c('q'), A::QuitOrBack),
                // Handled everywhere before this ([`Ctx::Always`]); named here for the help.
                Bind {
                    key: Key::Ctrl('c'),
                    action: A::Quit,
                    shown: Shown::As("^C"),
                },
                hidden(k(K::Esc), A::Timeline),
            ],
            "help / quit (q: back from a view)",
        ),
        &[(0, "?:help"), (4, "q:quit")],
    ),
    unlisted(
        Ctx::Help,
        &[
            b(c('q'), A::CloseHelp),
            b(c('?'), A::CloseHelp),
            b(k(K::Esc), A::CloseHelp),
            b(k(K::Enter), A::CloseHelp),
            b(c('j'), A::Move(M::Down)),
            b(k(K::Down), A::Move(M::Down)),
            b(c('k'), A::Move(M::Up)),
            b(k(K::Up), A::Move(M::Up)),
            b(k(K::PageDown), A::Move(M::PageDown)),
            b(c(' '), A::Move(M::PageDown)),
            b(k(K::PageUp), A::Move(M::PageUp)),
            b(c('g'), A::Move(M::Top)),
            b(k(K::Home), A::Move(M::Top)),
            b(c('G'), A::Move(M::Bottom)),
            b(k(K::End), A::Move(M::Bottom)),
        ],
    ),
    unlisted(
        Ctx::Input,
        &[
            b(k(K::Esc), A::Cancel),
            b(k(K::Backspace), A::DeleteChar),
            b(Key::Ctrl('u'), A::ClearLine),
            b(k(K::Enter), A::Commit),
        ],
    ),
];

/// What key `k` does in `ctx` (the first binding of the list that matches).
pub fn action(ctx: Ctx, k: &KeyEvent) -> Option<Action> {
    KEYS.iter()
        .filter(|e| e.ctx == ctx)
        .flat_map(|e| e.binds)
        .find(|b| b.key.matches(k))
        .map(|b| b.action)
}

/// The help overlay's key column of an entry: the names of its shown keys (or its label).
pub fn label(e: &Entry) -> String {
    match e.label {
        Some(l) => l.to_string(),
        None => e
            .binds
            .iter()
            .filter_map(|b| match b.shown {
                Shown::Name => Some(b.key.name()),
                Shown::Hidden => None,
                Shown::As(s) => Some(s.to_string()),
            })
            .collect::<Vec<_>>()
            .join(" "),
    }
}

/// The help overlay's key lines: (keys, what they do), in the list's order.
pub fn help_rows() -> Vec<(String, &'static str)> {
    KEYS.iter()
        .filter_map(|e| Some((label(e), e.help?)))
        .collect()
}

/// The status bar's hints, most useful first.
pub fn hints() -> Vec<&'static str> {
    let mut all: Vec<(u8, &'static str)> =
        KEYS.iter().flat_map(|e| e.hints.iter().copied()).collect();
    all.sort_by_key(|h| h.0);
    all.into_iter().map(|h| h.1).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The help overlay reads as it did when it was a table of its own.
    #[test]
    fn help_names_the_keys() {
        let rows: Vec<String> = help_rows().into_iter().map(|r| r.0).collect();
        assert_eq!(
            rows,
            [
                "j k ↑ ↓",
                "g G Home End",
                "PgUp PgDn ^u ^d",
                "Tab S-Tab",
                "Enter space h l",
                "< >",
                "a",
                "A",
                "&",
                "/",
                "s",
                "n N",
                "p",
                ":",
                "t",
                "f",
                "1 2 3",
                "mouse",
                "? q ^C",
            ]
        );
        assert_eq!(
            hints(),
            [
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
            ]
        );
    }

    /// No key does two things in one context (the first would hide the second).
    #[test]
    fn no_key_is_bound_twice() {
        for ctx in [Ctx::Always, Ctx::Input, Ctx::Help, Ctx::Main] {
            let keys: Vec<Key> = KEYS
                .iter()
                .filter(|e| e.ctx == ctx)
                .flat_map(|e| e.binds)
                .map(|b| b.key)
                .collect();
            for (i, key) in keys.iter().enumerate() {
                assert!(!keys[..i].contains(key), "{key:?} twice in {ctx:?}");
            }
        }
    }
}
