//! The terminal UI over any capture, as `aptscope view` opens it: the index built from the
//! reader `decode` picks (records packed, their bytes in the scratch arena file the viewer
//! writes), then the screen drawn with ratatui's `TestBackend` while keys are pressed.
//!
//! Input: `[flags, size, keys…(16), file…]`: `flags % 3` is the protocol (auto, apt,
//! elliptec); `size % 5` picks the screen (80×24, 160×48, 30×8, 12×4, 1×1: layouts that
//! leave a pane no room); each key byte names one of `KEYS` (the viewer's bindings, and
//! characters to type into the filter, search and go-to bars). Checks: every record of the
//! index is the NDJSON object `decode --json` prints for it (the index's late `no_reply`
//! diagnostics aside, which the NDJSON gives as their own lines: their records are flagged
//! instead), and there are as many; every record has a timeline row and a detail tree; drawing
//! after each key never panics.

use crate::decode_pipeline::reader;
use crate::util::{expansion_limit, split_ctl};
use aptscope_capture::open::sniff;
use aptscope_capture::Event;
use aptscope_dissector::detect::Proto;
use aptscope_dissector::pipeline::{Format as PFormat, Pipeline};
use aptscope_dissector::units::UnitsOpts;
use aptscope_tui::app::App;
use aptscope_tui::index::{Indexer, Shared, F_NO_REPLY};
use aptscope_tui::ui::draw;
use ratatui::backend::TestBackend;
use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::Terminal;
use serde_json::Value;
use std::sync::Arc;

/// The keys a key byte names (modulo their number): the viewer's bindings (tui/src/keys.rs),
/// then characters of filters and numbers.
const KEYS: &[(KeyCode, bool)] = &[
    (KeyCode::Char('j'), false),
    (KeyCode::Char('k'), false),
    (KeyCode::Char('g'), false),
    (KeyCode::Char('G'), false),
    (KeyCode::Char('h'), false),
    (KeyCode::Char('l'), false),
    (KeyCode::Char('n'), false),
    (KeyCode::Char('N'), false),
    (KeyCode::Char('p'), false),
    (KeyCode::Char('P'), false),
    (KeyCode::Char('s'), false),
    (KeyCode::Char('S'), false),
    (KeyCode::Char('t'), false),
    (KeyCode::Char('a'), false),
    (KeyCode::Char('A'), false),
    (KeyCode::Char('f'), false),
    (KeyCode::Char('F'), false),
    (KeyCode::Char('q'), false),
    (KeyCode::Char('?'), false),
    (KeyCode::Char('/'), false),
    (KeyCode::Char(':'), false),
    (KeyCode::Char('&'), false),
    (KeyCode::Char('<'), false),
    (KeyCode::Char('>'), false),
    (KeyCode::Char('1'), false),
    (KeyCode::Char('2'), false),
    (KeyCode::Char('3'), false),
    (KeyCode::Char(' '), false),
    (KeyCode::Up, false),
    (KeyCode::Down, false),
    (KeyCode::Left, false),
    (KeyCode::Right, false),
    (KeyCode::PageUp, false),
    (KeyCode::PageDown, false),
    (KeyCode::Home, false),
    (KeyCode::End, false),
    (KeyCode::Tab, false),
    (KeyCode::BackTab, false),
    (KeyCode::Enter, false),
    (KeyCode::Esc, false),
    (KeyCode::Backspace, false),
    (KeyCode::Char('d'), true),
    (KeyCode::Char('u'), true),
    (KeyCode::Char('b'), true),
    (KeyCode::Char('0'), false),
    (KeyCode::Char('9'), false),
    (KeyCode::Char('x'), false),
    (KeyCode::Char('='), false),
    (KeyCode::Char('~'), false),
    (KeyCode::Char('.'), false),
    (KeyCode::Char('"'), false),
    (KeyCode::Char('M'), false),
    (KeyCode::Char('_'), false),
    (KeyCode::Char('e'), false),
];

/// The screens a size byte names.
const SIZES: [(u16, u16); 5] = [(80, 24), (160, 48), (30, 8), (12, 4), (1, 1)];

/// The target's body: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let ([flags, size, keys @ ..], file) = split_ctl::<18>(data);
    let proto = match flags % 3 {
        0 => None,
        1 => Some(Proto::Apt),
        _ => Some(Proto::Elliptec),
    };
    let shared = index(file, proto);
    check_records(file, proto, &shared);
    let (w, h) = SIZES[usize::from(size) % SIZES.len()];
    let mut app = App::new(shared, "fuzz", false);
    let mut t = Terminal::new(TestBackend::new(w, h)).expect("terminal");
    // As the viewer's loop: drawn (the state fitted to the screen first) before each key and
    // after the last.
    t.draw(|f| draw(f, &mut app)).expect("draw");
    for &k in &keys {
        let (code, ctrl) = KEYS[usize::from(k) % KEYS.len()];
        let m = if ctrl {
            KeyModifiers::CONTROL
        } else {
            KeyModifiers::NONE
        };
        app.on_key(KeyEvent::new(code, m));
        t.draw(|f| draw(f, &mut app)).expect("draw");
    }
}

/// The index of `file` as the viewer builds it (in this thread), the capture ended where
/// [`expansion_limit`] says.
fn index(file: &[u8], proto: Option<Proto>) -> Arc<Shared> {
    let shared = Arc::new(Shared::default());
    let mut ix = Indexer::new(shared.clone(), proto, UnitsOpts::default());
    let mut r = reader(file, sniff(head(file)));
    let mut bytes = 0usize;
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = &ev {
            bytes += c.bytes.len();
        }
        ix.event(ev);
        if bytes > expansion_limit(file.len()) {
            break;
        }
    }
    ix.finish();
    shared
}

/// What `sniff` reads of a file.
fn head(file: &[u8]) -> &[u8] {
    &file[..file.len().min(aptscope_capture::open::SNIFF_LEN)]
}

/// The index holds the records `decode --json` prints, each as it prints it, with a row and a
/// detail tree; the records that late `no_reply` lines name are flagged.
fn check_records(file: &[u8], proto: Option<Proto>, shared: &Shared) {
    let mut r = reader(file, sniff(head(file)));
    let mut p = Pipeline::new(proto, PFormat::Json);
    let mut out: Vec<Value> = vec![];
    let mut emit = |l: &str| -> Result<(), ()> {
        out.push(serde_json::from_str(l).expect("NDJSON"));
        Ok(())
    };
    let mut bytes = 0usize;
    while let Some(ev) = r.next_event() {
        if let Event::Chunk(c) = &ev {
            bytes += c.bytes.len();
        }
        ev.feed(&mut p, &mut emit).expect("pipeline");
        if bytes > expansion_limit(file.len()) {
            break;
        }
    }
    p.finish(&mut emit).expect("pipeline");
    let ix = shared.index.read().expect("index");
    assert!(ix.done, "index not complete");
    let mut count = 0;
    for want in out.iter().filter(|v| v.get("n").is_some()) {
        let n = want["n"].as_u64().expect("n");
        let got = aptscope_tui::decode::json_of(&ix, n).expect("record in the index");
        let mut got: Value = serde_json::from_str(&got).expect("JSON");
        if let Some(d) = got["diag"].as_array_mut() {
            d.retain(|x| x["kind"] != "no_reply");
        }
        assert_eq!(&got, want, "record {n}");
        assert!(aptscope_tui::decode::row(&ix, n).is_some(), "row {n}");
        assert!(!aptscope_tui::decode::tree(&ix, n).is_empty(), "tree {n}");
        count += 1;
    }
    assert_eq!(count, ix.recs.len(), "records");
    for v in out.iter().filter(|v| v["type"] == "diag") {
        let is_no_reply = v["diag"]
            .as_array()
            .is_some_and(|d| d.iter().any(|x| x["kind"] == "no_reply"));
        if let (Some(n), true) = (v["ref"].as_u64(), is_no_reply) {
            let rec = ix.rec(n).expect("the record a late line names");
            assert!(rec.has(F_NO_REPLY), "record {n} not flagged");
        }
    }
}
