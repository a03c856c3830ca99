//! The viewer on a growing index (a live source): the timeline follows new records (LIVE),
//! stops following when the user scrolls up (PAUSED, with the count of records not seen), `G`
//! follows again; filters and statistics extend as records arrive.

use aptscope_dissector::apt::{encode_named, Named};
use aptscope_dissector::detect::Proto;
use aptscope_dissector::record::Ctx;
use aptscope_dissector::table::Dir;
use aptscope_dissector::Table;
use aptscope_tui::app::App;
use aptscope_tui::index::{Indexer, Shared};
use aptscope_tui::ui::draw;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::Terminal;
use std::sync::Arc;

fn frame(name: &str, values: &[(&str, &str)], dst: u8, src: u8) -> Vec<u8> {
    let n = Named {
        name,
        sub: None,
        values,
        form: None,
        dst,
        src,
    };
    encode_named(Table::global(), &n).expect("valid frame")
}

/// A source that talks: each step, the host asks for a status update and the controller
/// answers, 10 ms apart.
struct Source {
    ix: Indexer,
    t: u64,
    pos: i64,
}

impl Source {
    fn new(shared: &Arc<Shared>) -> Self {
        Source {
            ix: Indexer::new(shared.clone(), Some(Proto::Apt), Default::default()),
            t: 1_700_000_000_000_000_000,
            pos: 0,
        }
    }

    /// `n` request/reply exchanges, published.
    fn exchanges(&mut self, n: usize) {
        for _ in 0..n {
            let req = frame("MOT_REQ_STATUSUPDATE", &[("chan_ident", "1")], 0x50, 0x01);
            self.chunk(Dir::HostToDevice, &req);
            self.pos += 100;
            let p = self.pos.to_string();
            let rep = frame(
                "MOT_GET_STATUSUPDATE",
                &[("chan_ident", "1"), ("position", &p)],
                0x01,
                0x50,
            );
            self.chunk(Dir::DeviceToHost, &rep);
        }
        self.ix.flush();
    }

    fn chunk(&mut self, dir: Dir, bytes: &[u8]) {
        self.t += 10_000_000;
        let ctx = Ctx {
            stream: 0,
            dir: Some(dir),
            ts_ns: Some(self.t),
        };
        self.ix.chunk(ctx, bytes);
    }
}

fn key(app: &mut App, c: KeyCode) {
    app.on_key(KeyEvent::new(c, KeyModifiers::NONE));
}

fn screen(app: &mut App, t: &mut Terminal<TestBackend>) -> String {
    t.draw(|f| draw(f, app)).expect("draw");
    format!("{}", t.backend())
}

fn status_line(s: &str) -> String {
    s.lines().last().unwrap_or("").to_string()
}

#[test]
fn live_view_follows_pauses_and_resumes() {
    let shared = Arc::new(Shared::default());
    let mut src = Source::new(&shared);
    let mut app = App::new(shared.clone(), "live", false);
    app.set_live(true);
    let mut t = Terminal::new(TestBackend::new(80, 24)).expect("terminal");
    // Nothing yet: live, waiting.
    let s = screen(&mut app, &mut t);
    assert!(status_line(&s).contains("LIVE"), "{s}");

    src.exchanges(3);
    let s = screen(&mut app, &mut t);
    assert_eq!(app.len(), 6);
    assert_eq!(app.selected(), Some(6), "follows the newest record");
    insta::assert_snapshot!("live_following_80x24", s);

    src.exchanges(20);
    let s = screen(&mut app, &mut t);
    assert_eq!(app.selected(), Some(46), "still following");
    assert!(s.contains("MOT_GET_STATUSUPDATE"));
    assert!(status_line(&s).contains("LIVE"), "{s}");

    // The user scrolls up: the view stays where it is, new records are counted.
    for _ in 0..3 {
        key(&mut app, KeyCode::Char('k'));
    }
    let s = screen(&mut app, &mut t);
    assert!(!app.following());
    assert!(status_line(&s).contains("PAUSED · 0 new"), "{s}");
    src.exchanges(5);
    let s = screen(&mut app, &mut t);
    assert_eq!(app.selected(), Some(43), "the selection stays put");
    assert_eq!(app.len(), 56);
    assert_eq!(app.unseen(), 10);
    assert!(status_line(&s).contains("PAUSED · 10 new"), "{s}");
    insta::assert_snapshot!("live_paused_80x24", s);

    // `G` goes to the end and follows again.
    key(&mut app, KeyCode::Char('G'));
    src.exchanges(1);
    let s = screen(&mut app, &mut t);
    assert!(app.following());
    assert_eq!(app.selected(), Some(58));
    assert!(status_line(&s).contains("LIVE"), "{s}");
    // `f` toggles.
    key(&mut app, KeyCode::Char('f'));
    let s = screen(&mut app, &mut t);
    assert!(status_line(&s).contains("PAUSED"), "{s}");
    key(&mut app, KeyCode::Char('f'));
    let s = screen(&mut app, &mut t);
    assert!(status_line(&s).contains("LIVE"), "{s}");

    // The end of the source.
    src.ix.finish();
    let s = screen(&mut app, &mut t);
    assert!(status_line(&s).contains("ENDED"), "{s}");
}

#[test]
fn filters_statistics_and_plot_extend_as_records_arrive() {
    let shared = Arc::new(Shared::default());
    let mut src = Source::new(&shared);
    let mut app = App::new(shared.clone(), "live", false);
    app.set_live(true);
    let mut t = Terminal::new(TestBackend::new(100, 30)).expect("terminal");
    src.exchanges(4);
    app.apply_filter("apt.name == MOT_GET_STATUSUPDATE && apt.position > 200");
    let _ = screen(&mut app, &mut t);
    assert_eq!(app.rows(0, 100), vec![6, 8]);
    src.exchanges(2);
    let _ = screen(&mut app, &mut t);
    assert_eq!(app.rows(0, 100), vec![6, 8, 10, 12]);
    assert_eq!(app.selected(), Some(12), "the filtered view follows too");
    {
        let st = app.scan().state.lock().expect("lock");
        assert_eq!(st.scanned, 12);
        assert_eq!(st.stats.frames.count, 4, "statistics of the matches");
        assert!(!st.done, "a live scan is not over");
    }
    // Pairing reaches records published earlier: every request is answered.
    app.apply_filter("unpaired");
    src.exchanges(1);
    let _ = screen(&mut app, &mut t);
    assert!(app.rows(0, 100).is_empty(), "{:?}", app.rows(0, 100));
    let ix = shared.index.read().expect("lock");
    let pts = ix
        .series
        .iter()
        .find(|(k, _)| k.starts_with("position"))
        .map(|(_, v)| v.len());
    assert_eq!(pts, Some(7), "{:?}", ix.series.keys());
}

/// A request that is never answered shows `!! no reply` on its row once its timeout passes: the
/// statistics count it then too (it used to show "Diagnostics: none" until a filter was applied
/// and cleared), with no filter and with a filter that showed the row before.
#[test]
fn statistics_count_a_no_reply_that_comes_after_its_row() {
    for filter in [None, Some("apt.name ~ \"REQ\"")] {
        let shared = Arc::new(Shared::default());
        let mut src = Source::new(&shared);
        let mut app = App::new(shared.clone(), "live", false);
        app.set_live(true);
        let mut t = Terminal::new(TestBackend::new(100, 30)).expect("terminal");
        if let Some(f) = filter {
            app.apply_filter(f);
        }
        // An unanswered request, then traffic for a while (its 2 s timeout passes).
        let req = frame("HW_REQ_INFO", &[], 0x50, 0x01);
        src.chunk(Dir::HostToDevice, &req);
        src.ix.flush();
        let _ = screen(&mut app, &mut t);
        let count = |app: &App| {
            let st = app.scan().state.lock().expect("lock");
            st.stats.diags.get("no_reply").copied()
        };
        assert_eq!(count(&app), None);
        for _ in 0..30 {
            src.exchanges(5);
            let _ = screen(&mut app, &mut t);
        }
        let ix = shared.index.read().expect("lock");
        assert!(
            ix.rec(1)
                .is_some_and(|r| r.flags & aptscope_tui::index::F_NO_REPLY != 0),
            "the row shows no reply"
        );
        drop(ix);
        // The viewer without background threads scans, and rebuilds the statistics, as it
        // draws.
        assert_eq!(count(&app), Some(1), "filter {filter:?}");
        // The title says LIVE (not "[indexing 0%]" forever), and a filter that has caught up
        // is not "filtering…".
        let sc = screen(&mut app, &mut t);
        let title = sc.lines().next().unwrap_or("");
        assert!(
            title.contains("LIVE") && !title.contains("indexing"),
            "{title}"
        );
        assert!(!title.contains("filtering"), "{title}");
    }
}
